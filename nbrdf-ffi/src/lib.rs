//! C ABI of nbrdf (see `include/nbrdf.h`). Filled in by the FFI work.
