"""The daemon's loop under hostile or stuck peers: nothing may block it or kill it."""

import socket
import threading

from hilgate.core import notify as sdnotify


def test_sd_notify_never_blocks_when_nobody_reads(tmp_path, monkeypatch):
    path = str(tmp_path / "notify")
    reader = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    reader.bind(path)  # bound, never read: its queue fills after a few datagrams
    monkeypatch.setenv("NOTIFY_SOCKET", path)
    before = sdnotify.dropped
    results = []
    worker = threading.Thread(target=lambda: results.extend(sdnotify.notify("STATUS=x" * 100) for _ in range(500)))
    worker.daemon = True
    worker.start()
    worker.join(60)  # a hang detector, not a speed bound: a blocking send never returns
    assert not worker.is_alive(), "sd_notify blocked on a socket nobody reads"
    assert len(results) == 500 and results[0] is True
    assert sdnotify.dropped - before == results.count(False) > 0
    reader.close()
