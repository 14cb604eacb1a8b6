//! Camera JSON: the INRIA cameras.json and semsplat's own camera JSON.
