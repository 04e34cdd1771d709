//! The C API's integration tests, one binary (one link of the engine
//! instead of one per file).

mod boundary;
mod c_program;
mod header;
