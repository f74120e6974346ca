"""The operator's view in a browser: ``hilgate run --web`` (live) and ``hilgate view TRACE`` (a trace played).

:mod:`.picture` turns a scene and events in the trace's vocabulary into what the page draws (sans-I/O);
:mod:`.replay` indexes a trace for the player; :mod:`.server` serves the page and its WebSocket from a
thread of its own (tornado, an optional extra: ``pip install 'hilgate[web]'``).
"""
