"""The Generic Link Interface: the socket framing, the dccomms POSIX queues, the socket endpoints and
the client library."""
