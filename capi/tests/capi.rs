//! The C ABI's integration tests, one binary: the header is current ([`header`]), and C / C++
//! programs compiled with the system compilers against `libfrictionless.so` and `.a` agree with the
//! core and with `frictl predict`, refuse bad files with the right codes, and run clean under
//! valgrind (or ASan) ([`c_program`], [`cpp_example`]).

mod c_program;
mod cpp_example;
mod header;
mod support;
