//! Loading cameras from any supported format (detected from the path).
