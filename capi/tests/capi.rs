//! The C ABI's integration tests, one binary: the header is current ([`header`]), and C / C++
//! programs compiled with the system compilers against `libfrictionless.so` and `.a` agree with the
//! core and with `frictl predict`, refuse bad files with the right codes, and run clean under
//! valgrind (or ASan) ([`c_program`], [`cpp_example`]); the control client against a live
//! `frictiond`, in-process and from C ([`control`]).

mod c_program;
mod control;
mod cpp_example;
mod header;
mod support;
