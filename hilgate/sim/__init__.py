"""A scene made live in virtual or real time: the world (medium, modems, poses, flows), the recorder
(trace and metrics) and ``hilgate sim``."""
