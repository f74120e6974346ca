"""In-process cost of one daemon pass: app frame on a's queue -> frame in b's queue (+ states).

Run from the repository root: `python benchmarks/pass_cost.py [N]` prints the p10/p50/p90 of N passes;
`PROF=1` adds a cProfile table.  Used to judge a compiled hot path: docs/compiled-hot-path.md."""
import sys, os, time, tempfile, cProfile, pstats
sys.path.insert(0, os.path.join(os.getcwd(), "benchmarks"))
import gli_roundtrip as g
import posix_ipc
from hilgate.daemon import service
from hilgate.core.realtime import RealtimeScheduler
N = int(sys.argv[1]) if len(sys.argv) > 1 else 20000
PROFILE = os.environ.get("PROF")
a, b = f"ppa{os.getpid()}", f"ppb{os.getpid()}"
d = tempfile.mkdtemp()
scene = os.path.join(d, "s.yaml"); open(scene, "w").write(g.SCENE.format(a=a, b=b))
result = {}
def fake_run(self, until=float("inf")):
    self.start_clock()
    import gc; gc.disable()
    tx = posix_ipc.MessageQueue(f"/{a}_tx_dlnk_phy"); rxa = posix_ipc.MessageQueue(f"/{a}_rx_dlnk_phy")
    rxb = posix_ipc.MessageQueue(f"/{b}_rx_dlnk_phy"); txb = posix_ipc.MessageQueue(f"/{b}_tx_dlnk_phy")
    txb.send(b"\x01"); tx.send(b"\x01")
    self._handle_inputs(0.0); self._fire_due(self.model_time())
    def drain(q):
        n = 0
        while True:
            try: q.receive(0); n += 1
            except posix_ipc.BusyError: return n
    drain(rxa); drain(rxb)
    msg = g.frame(b"ping" * 5, 0, 2)
    samples = []; states = frames = 0
    prof = cProfile.Profile() if PROFILE else None
    for i in range(N):
        tx.send(msg)
        t0 = time.perf_counter()
        if prof: prof.enable()
        self._handle_inputs(0.0)
        while self.peek() <= self.model_time():
            self._fire_due(self.model_time())
        if self._deferred: self.run_deferred()
        if prof: prof.disable()
        samples.append(time.perf_counter() - t0)
        states += drain(rxa); frames += drain(rxb)
    samples.sort()
    print(f"pass p50 {samples[N//2]*1e6:.1f} us, p10 {samples[N//10]*1e6:.1f}, p90 {samples[9*N//10]*1e6:.1f}; state msgs/frame {states/N:.2f}, frames {frames}")
    if prof:
        pstats.Stats(prof).sort_stats("tottime").print_stats(200)
    for q in (tx, rxa, rxb, txb): q.close()
    return 0
class PassScheduler(RealtimeScheduler):
    """A subclass, not a patched class: a class compiled by mypyc is closed (docs/compiled-hot-path.md)."""
    run = fake_run
service.RealtimeScheduler = PassScheduler
dm = service.Daemon(scene, runtime_dir=os.path.join(d, "rt"))
try:
    dm.run()
finally:
    from hilgate.gli.queues import unlink_queues
    unlink_queues((a, b))
