//! Procedural benchmark rooms with exact ground truth and label-noise models.
