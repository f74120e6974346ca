#!/usr/bin/env python3
"""realtime_lateness.py's scene in ns-3's own real-time scheduler: the peer beside hilgate and the bare loop.

Run by ``realtime_lateness.py`` with a Python that has the PyPI wheel ``ns3`` (``--ns3-python``), never
by the project's own: N UAN nodes on a ring of ``--radius`` m (node i at angle 2πi/N, as hilgate's scene),
one FSK mode at ``--bitrate`` bit/s, ideal propagation at 1500 m/s, ``UanMacAloha`` (no queue, no ACK), half
duplex; every node broadcasts ``--size``-byte payloads (3 bytes of UAN header on top) as a Poisson process
of ``--rate`` a second with gaps of at least ``--min-gap`` s, for ``--sim-time`` s, under
``ns3::RealtimeSimulatorImpl`` (``BestEffort``: late events run late, none is skipped).

At every reception that ends well (the PHY's ``RxOk``: the model's delivery time, as hilgate's), plain C++
(no Python in the hot path) writes the wall-clock time (CLOCK_MONOTONIC, the benchmark's ``perf_counter``)
at which the event was due to the SOCK_SEQPACKET descriptor ``--fd``, as 8 bytes; the benchmark's reader
stamps its receipt.  So the lateness it measures is the bare loop's: a timer's lateness plus one hop to
another process, here with ns-3's scheduler and UAN model in front.  The descriptor is closed at the end
(the reader sees end of file), then one JSON line is printed: deliveries written, sends, and the
scheduler's own lateness at the delivery events (before the hop) mean and max.

``--realtime-priority P`` runs its simulation thread as ``hilgate run --realtime-priority P`` runs the
daemon's loop (``hilgate.core.priority``): SCHED_RR at P for that thread alone (``SCHED_RESET_ON_FORK``),
memory locked as it is touched, taken once the scene is built (cling's compiling at start-up, seconds of
CPU, is not run at real-time priority, as the daemon's start-up is not).  Where it is refused, ns-3
runs at normal priority and says so on stderr.
"""

import argparse
import ctypes
import json
import math
import os
import sys
import time


def parse_args():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--fd", type=int, required=True, help="SOCK_SEQPACKET descriptor for the due times")
    p.add_argument("--nodes", type=int, default=50)
    p.add_argument("--sim-time", type=float, default=20.0, help="seconds of sending")
    p.add_argument("--rate", type=float, default=0.5, help="frames per second per node")
    p.add_argument("--min-gap", type=float, default=0.05, help="s between one node's frames, at least")
    p.add_argument("--size", type=int, default=17, help="payload bytes (20 on air with the UAN header)")
    p.add_argument("--bitrate", type=int, default=9600)
    p.add_argument("--radius", type=float, default=200.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--realtime-priority", type=int, default=0)
    return p.parse_args()


CPP = r"""
#include <time.h>
#include <unistd.h>
namespace hilrt {
  static int fd = -1;
  static ns3::Ptr<ns3::RealtimeSimulatorImpl> rt;
  static uint64_t sent = 0, delivered = 0, writeErrors = 0;
  static double lateSum = 0, lateMax = 0;
  struct Src { ns3::Ptr<ns3::Socket> s; ns3::Ptr<ns3::ExponentialRandomVariable> gap;
               uint32_t size; double stop; double minGap; };
  void MarkStart(int out) {
    fd = out;
    rt = ns3::DynamicCast<ns3::RealtimeSimulatorImpl>(ns3::Simulator::GetImplementation());
  }
  void Fire(Src* x) {
    if (ns3::Simulator::Now().GetSeconds() >= x->stop) { return; }
    x->s->Send(ns3::Create<ns3::Packet>(x->size)); ++sent;
    double gap = x->gap->GetValue(); if (gap < x->minGap) { gap = x->minGap; }
    ns3::Simulator::Schedule(ns3::Seconds(gap), &Fire, x);
  }
  void StartPoisson(ns3::Ptr<ns3::Node> n, ns3::Ptr<ns3::NetDevice> dev, double rate, uint32_t size,
                    double stop, double minGap) {
    using namespace ns3;
    PacketSocketAddress dst;  // broadcast from this node's device
    dst.SetSingleDevice(dev->GetIfIndex());
    dst.SetPhysicalAddress(dev->GetBroadcast());
    dst.SetProtocol(0);
    Src* x = new Src;  // lives for the whole run
    x->s = Socket::CreateSocket(n, TypeId::LookupByName("ns3::PacketSocketFactory"));
    x->s->Bind(); x->s->Connect(Address(dst));
    x->gap = CreateObject<ExponentialRandomVariable>();
    x->gap->SetAttribute("Mean", DoubleValue(1.0 / rate));
    x->size = size; x->stop = stop; x->minGap = minGap;
    Simulator::Schedule(Seconds(x->gap->GetValue()), &Fire, x);
  }
  void RxOk(ns3::Ptr<const ns3::Packet>, double, ns3::UanTxMode) {
    double late = (rt->RealtimeNow() - ns3::Simulator::Now()).GetSeconds();
    struct timespec now; clock_gettime(CLOCK_MONOTONIC, &now);
    double due = now.tv_sec + 1e-9 * now.tv_nsec - late;
    ++delivered; lateSum += late; if (late > lateMax) { lateMax = late; }
    if (write(fd, &due, sizeof due) != (ssize_t)sizeof due) { ++writeErrors; }
  }
  bool Hook() {
    return ns3::Config::ConnectWithoutContextFailSafe(
      "/NodeList/*/DeviceList/*/$ns3::UanNetDevice/Phy/RxOk", ns3::MakeCallback(&RxOk));
  }
  ns3::UanModesList OneMode(uint32_t bps) {
    ns3::UanModesList l;
    l.AppendMode(ns3::UanTxModeFactory::CreateMode(ns3::UanTxMode::FSK, bps, bps, 12000, bps, 2, "hil-fsk"));
    return l;
  }
}
"""


def take_priority(priority):
    """What hilgate.core.priority gives the daemon's loop where allowed (this Python has no hilgate)."""
    try:
        os.sched_setscheduler(0, os.SCHED_RR | os.SCHED_RESET_ON_FORK, os.sched_param(priority))
    except OSError as exc:
        print(f"ns3_realtime: SCHED_RR {priority} refused ({exc}): normal priority", file=sys.stderr)
        return
    libc = ctypes.CDLL(None, use_errno=True)
    if libc.mlockall(1 | 2 | 4) != 0:  # MCL_CURRENT | MCL_FUTURE | MCL_ONFAULT
        print(f"ns3_realtime: memory not locked ({os.strerror(ctypes.get_errno())})", file=sys.stderr)


def main():
    a = parse_args()
    from ns import ns  # slow: cppyy/cling JIT, seconds
    import cppyy

    cppyy.cppdef(CPP)
    hp = cppyy.gbl.hilrt
    ns.GlobalValue.Bind("SimulatorImplementationType", ns.StringValue("ns3::RealtimeSimulatorImpl"))
    ns.RngSeedManager.SetSeed(a.seed)
    ns.Config.SetDefault("ns3::UanPhyGen::SupportedModes", ns.UanModesListValue(hp.OneMode(a.bitrate)))

    nodes = ns.NodeContainer()
    nodes.Create(a.nodes)
    mob = ns.MobilityHelper()
    pos = ns.CreateObject[ns.ListPositionAllocator]()
    for i in range(a.nodes):
        th = 2 * math.pi * i / a.nodes
        pos.Add(ns.Vector(a.radius * math.cos(th), a.radius * math.sin(th), 0.0))
    mob.SetPositionAllocator(pos)
    mob.SetMobilityModel("ns3::ConstantPositionMobilityModel")
    mob.Install(nodes)
    uan = ns.UanHelper()  # UanPhyGen + UanMacAloha + UanTransducerHd
    chan = ns.CreateObject[ns.UanChannel]()
    chan.SetPropagationModel(ns.CreateObject[ns.UanPropModelIdeal]())
    chan.SetNoiseModel(ns.CreateObject[ns.UanNoiseModelDefault]())
    devs = uan.Install(nodes, chan)
    ns.PacketSocketHelper().Install(nodes)
    for i in range(a.nodes):
        hp.StartPoisson(nodes.Get(i), devs.Get(i), a.rate, a.size, a.sim_time, a.min_gap)
    if not hp.Hook():
        print("ns3_realtime: could not hook the PHY's RxOk", file=sys.stderr)
        return 1
    ns.Simulator.Stop(ns.Seconds(a.sim_time + 1.0))
    if a.realtime_priority:
        take_priority(a.realtime_priority)
    hp.MarkStart(a.fd)
    t0 = time.perf_counter()
    ns.Simulator.Run()
    wall = time.perf_counter() - t0
    ns.Simulator.Destroy()
    os.close(a.fd)
    print(json.dumps({
        "nodes": a.nodes, "sent": int(hp.sent), "delivered": int(hp.delivered), "write_errors": int(hp.writeErrors),
        "wall_s": round(wall, 3),
        "event_lateness_mean_ms": round(1e3 * hp.lateSum / hp.delivered, 4) if hp.delivered else None,
        "event_lateness_max_ms": round(1e3 * hp.lateMax, 4)}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
