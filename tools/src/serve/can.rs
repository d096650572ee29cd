//! `frictl sim serve --backend can`: the virtual joints as motor drives on SocketCAN (being built,
//! issue #6).
