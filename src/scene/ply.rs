//! PLY read/write in the INRIA 3DGS layout, plus semantic properties.
