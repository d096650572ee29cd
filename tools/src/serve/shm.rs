//! `frictl sim serve --backend shm`: the virtual joints over iceoryx2 (being built, issue #3).
