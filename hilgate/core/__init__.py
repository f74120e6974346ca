"""The core every room builds on: the event scheduler (virtual and real time), non-blocking streams,
GLI packet classes, the backend interface, systemd notification, bounded JSON."""
