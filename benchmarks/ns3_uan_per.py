"""PER against distance: hilgate's physical model beside ns-3 UAN's, for identical parameters.

The issue's cross-check (issue 16): Thorp absorption, spreading k = 1.5, shipping s = 0.5, wind 0,
one band and one modulation (coherent BPSK, bandwidth = bit rate so that Eb/N0 = SNR as ns-3 takes
it), the noise as ns-3's UanPhyGen computes it (N(fc)·B: ``noise_band: centre``).  For each distance
it prints the analytic PER, hilgate's simulated PER and ns-3's simulated PER (UanPhyGen with
UanPhyPerCommonModes, UanPropModelThorp, UanNoiseModelDefault; RxThreshold lowered so that every
arrival is judged), each simulated one with its z-score against the analytic value.  Frames are
sent one at a time (no collisions); both put the same number of bytes on air (payload + ns-3's
3-byte UAN header).

ns-3 runs only when its Python wheel is installed (``pip install ns3``: ~520 MB, several minutes to
build, ~7 s to import; that is why this is a benchmark and not part of ``make test``).  Without it,
its column says "not run" and nothing is made up in its place.  Usage:

    .venv/bin/python benchmarks/ns3_uan_per.py [--frames 2000] [--distances 2000 3000 …] [--ns3-python VENV/bin/python]

``--ns3-python`` runs the ns-3 side in another interpreter (the one whose venv has the wheel).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import textwrap

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

UAN_HEADER = 3  # UanHeaderCommon: what ns-3's ALOHA MAC puts before the payload


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--frames", type=int, default=2000, help="frames per distance and engine")
    p.add_argument("--payload", type=int, default=29, help="payload bytes (+3 UAN header on air)")
    p.add_argument("--distances", type=float, nargs="+",
                   help="metres (default: where the analytic PER is 0.05, 0.25, 0.5, 0.75 and 0.95)")
    p.add_argument("--centre-khz", type=float, default=26.0)
    p.add_argument("--bitrate", type=float, default=4000.0, help="bit/s, also the bandwidth in Hz")
    p.add_argument("--source-level", type=float, default=125.0, help="dB re 1 µPa @ 1 m (ns-3 TxPower)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--ns3-python", default=sys.executable, help="interpreter with the ns3 wheel")
    p.add_argument("--ns3-only", action="store_true", help=argparse.SUPPRESS)  # the child process's mode
    return p.parse_args()


def model(a):
    from hilgate.models.physical import Acoustic, Environment, PhysicalErrorModel

    half = a.bitrate / 2000.0
    acoustic = Acoustic((a.centre_khz - half, a.centre_khz + half), a.source_level, modulation="bpsk")
    env = Environment(absorption="thorp", spreading=1.5, shipping=0.5, wind_mps=0.0, noise_band="centre")
    return PhysicalErrorModel(env, acoustic, a.bitrate)


def hilgate_per(a, d: float) -> tuple[int, int]:
    from hilgate.scene import load_scene_text
    from hilgate.sim.simulate import simulate

    half = a.bitrate / 2000.0
    size = a.payload + UAN_HEADER
    interval = 8 * size / a.bitrate + d / 1500.0 + 0.1
    scene = textwrap.dedent(f"""\
        channels: {{ac: {{speed_mps: 1500}}}}
        vehicles:
          a: {{pose: {{static: [0, 0, 0]}}}}
          b: {{pose: {{static: [{d}, 0, 0]}}}}
        links:
          la: &m
            vehicle: a
            bitrate_bps: {a.bitrate}
            acoustic: {{band_khz: [{a.centre_khz - half}, {a.centre_khz + half}], source_level_db: {a.source_level},
                        modulation: bpsk}}
            error: {{kind: physical, absorption: thorp, spreading: 1.5, shipping: 0.5, wind_mps: 0,
                     noise_band: centre}}
          lb: {{<<: *m, vehicle: b}}
        flows:
          - {{from: la, to: lb, size_bytes: {size}, interval_s: {interval}, stop_s: {interval * a.frames - 1e-6}}}
        """)
    summary = simulate(load_scene_text(scene, "<ns3-cross-check>"), until=interval * a.frames + 10, seed=a.seed)
    flow = summary["flows"][0]
    return flow["rx_packets"] + flow["lost"]["prop"], flow["lost"]["prop"]


NS3_CODE = r"""
namespace hilper {
  static uint64_t ok = 0, err = 0;
  void RxOk(ns3::Ptr<const ns3::Packet>, double, ns3::UanTxMode) { ++ok; }
  void RxErr(ns3::Ptr<const ns3::Packet>, double, ns3::UanTxMode) { ++err; }
  bool Hook(uint32_t node) {
    std::string base = "/NodeList/" + std::to_string(node) + "/DeviceList/*/$ns3::UanNetDevice/Phy/";
    bool a = ns3::Config::ConnectWithoutContextFailSafe(base + "RxOk", ns3::MakeCallback(&RxOk));
    bool b = ns3::Config::ConnectWithoutContextFailSafe(base + "RxError", ns3::MakeCallback(&RxErr));
    return a && b;
  }
  ns3::UanModesList Bpsk(uint32_t bps, uint32_t centreHz) {
    ns3::UanModesList modes;
    modes.AppendMode(ns3::UanTxModeFactory::CreateMode(ns3::UanTxMode::PSK, bps, bps, centreHz, bps, 2, "bpsk"));
    return modes;
  }
  void SendOne(ns3::Ptr<ns3::Socket> s, uint32_t size) { s->Send(ns3::Create<ns3::Packet>(size)); }
  void SendMany(ns3::Ptr<ns3::Socket> s, uint32_t size, uint32_t n, double start, double interval) {
    for (uint32_t i = 0; i < n; ++i) {
      ns3::Simulator::Schedule(ns3::Seconds(start + i * interval), &SendOne, s, size);
    }
  }
  ns3::Address ToAddress(const ns3::PacketSocketAddress& a) { return ns3::Address(a); }
}
"""


def ns3_per(a, d: float) -> tuple[int, int]:
    """One ns-3 run: node 1 at ``d`` m sends ``frames`` packets to node 0; PHY RxOk/RxError at node 0."""
    from ns import ns
    import cppyy

    cppyy.cppdef(NS3_CODE)
    hp = cppyy.gbl.hilper
    ns.RngSeedManager.SetSeed(a.seed)
    ns.Config.SetDefault("ns3::UanPhyGen::SupportedModes",
                         ns.UanModesListValue(hp.Bpsk(int(a.bitrate), int(a.centre_khz * 1000))))
    ns.Config.SetDefault("ns3::UanPhyGen::TxPower", ns.DoubleValue(a.source_level))
    ns.Config.SetDefault("ns3::UanPhyGen::RxThreshold", ns.DoubleValue(-1000.0))
    ns.Config.SetDefault("ns3::UanPhyGen::PerModel", ns.PointerValue(ns.CreateObject[ns.UanPhyPerCommonModes]()))
    nodes = ns.NodeContainer()
    nodes.Create(2)
    positions = ns.CreateObject[ns.ListPositionAllocator]()
    positions.Add(ns.Vector(0.0, 0.0, 0.0))
    positions.Add(ns.Vector(d, 0.0, 0.0))
    mobility = ns.MobilityHelper()
    mobility.SetPositionAllocator(positions)
    mobility.SetMobilityModel("ns3::ConstantPositionMobilityModel")
    mobility.Install(nodes)
    channel = ns.CreateObject[ns.UanChannel]()
    prop = ns.CreateObject[ns.UanPropModelThorp]()
    prop.SetAttribute("SpreadCoef", ns.DoubleValue(1.5))
    channel.SetPropagationModel(prop)
    noise = ns.CreateObject[ns.UanNoiseModelDefault]()
    noise.SetAttribute("Wind", ns.DoubleValue(0.0))
    noise.SetAttribute("Shipping", ns.DoubleValue(0.5))
    channel.SetNoiseModel(noise)
    devices = ns.UanHelper().Install(nodes, channel)
    ns.PacketSocketHelper().Install(nodes)
    dst = ns.PacketSocketAddress()
    dst.SetSingleDevice(devices.Get(1).GetIfIndex())
    dst.SetPhysicalAddress(devices.Get(0).GetAddress())
    dst.SetProtocol(0)
    socket = ns.Socket.CreateSocket(nodes.Get(1), ns.TypeId.LookupByName("ns3::PacketSocketFactory"))
    socket.Bind()
    socket.Connect(hp.ToAddress(dst))
    if not hp.Hook(0):
        raise RuntimeError("ns-3: could not connect the PHY traces")
    interval = 8 * (a.payload + UAN_HEADER) / a.bitrate + d / 1500.0 + 0.1
    hp.SendMany(socket, a.payload, a.frames, 1.0, interval)
    ns.Simulator.Stop(ns.Seconds(2.0 + a.frames * interval))
    ns.Simulator.Run()
    ns.Simulator.Destroy()
    return int(hp.ok + hp.err), int(hp.err)


def ns3_column(a) -> dict[float, tuple[int, int]] | str:
    """ns-3's counts per distance from a child interpreter, or why it did not run."""
    probe = subprocess.run([a.ns3_python, "-c", "import ns"], capture_output=True, text=True)
    if probe.returncode != 0:
        return "not run (the ns3 wheel is not installed for " + a.ns3_python + ")"
    out = {}
    for d in a.distances:
        args = [a.ns3_python, os.path.abspath(__file__), "--ns3-only", "--frames", str(a.frames), "--payload",
                str(a.payload), "--centre-khz", str(a.centre_khz), "--bitrate", str(a.bitrate), "--source-level",
                str(a.source_level), "--seed", str(a.seed), "--distances", str(d)]
        result = subprocess.run(args, capture_output=True, text=True)
        if result.returncode != 0:
            return "failed: " + (result.stderr.strip().splitlines() or ["?"])[-1]
        out[d] = tuple(json.loads(result.stdout.strip().splitlines()[-1]))
    return out


def z(n: int, k: int, p: float) -> str:
    if n == 0:
        return "-"
    sigma = math.sqrt(max(n * p * (1 - p), 1e-12))
    return f"{(k - n * p) / sigma:+.1f}"


def main() -> None:
    a = parse_args()
    if a.ns3_only:
        print(json.dumps(ns3_per(a, a.distances[0])))
        return
    m = model(a)
    size = a.payload + UAN_HEADER
    if not a.distances:
        from hilgate.sim.budget import crossing

        a.distances = [round(crossing(lambda d: m.per(d, size), p, 1.0, 1e5), 1) for p in (0.05, 0.25, 0.5, 0.75, 0.95)]
    ns3 = ns3_column(a)
    print(f"PER of {size}-byte frames (payload {a.payload} + UAN header), BPSK, {a.bitrate:g} bit/s in "
          f"{a.bitrate:g} Hz at {a.centre_khz:g} kHz, SL {a.source_level:g} dB, Thorp, k = 1.5, s = 0.5, w = 0; "
          f"{a.frames} frames per distance, seed {a.seed}")
    print(f"{'d m':>7} {'SNR dB':>7} {'analytic':>9} {'hilgate':>9} {'z':>6} {'ns-3':>9} {'z':>6}")
    for d in a.distances:
        p = m.per(d, size)
        n, k = hilgate_per(a, d)
        if isinstance(ns3, dict):
            n3, k3 = ns3[d]
            ns3_text = f"{k3 / n3 if n3 else float('nan'):9.4f} {z(n3, k3, p):>6}"
        else:
            ns3_text = f"{'-':>9} {'-':>6}"
        print(f"{d:7.0f} {m.snr_db(d):7.2f} {p:9.4f} {k / n:9.4f} {z(n, k, p):>6} {ns3_text}")
    if not isinstance(ns3, dict):
        print(f"ns-3: {ns3}")


if __name__ == "__main__":
    main()
