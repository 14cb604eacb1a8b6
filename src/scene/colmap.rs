//! COLMAP sparse models (cameras/images, .bin and .txt).
