//! Label maps (8/16-bit gray PNG) and palette-colored PNG output.
