"""Refactoring keeps behaviour: ``hilgate sim`` of every shipped scene writes, for a seed, the very
bytes it wrote before (``golden_traces.json``, recorded before the refactoring pass of issue 17).

A change that is meant to alter what the model does must say so and record new hashes
(``python tests/test_trace_identity.py --record``), never pass by accident."""

import hashlib
import json
import os
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
SCENES = os.path.join(HERE, "..", "scenes")
GOLDEN = os.path.join(HERE, "golden_traces.json")


def trace_hash(scene: str, seed: int, until: float, out: str) -> str:
    subprocess.run([sys.executable, "-m", "hilgate", "sim", os.path.join(SCENES, scene), "--seed", str(seed),
                    "--until", str(until), "--trace", out, "-q"], check=True, timeout=600)
    with open(out, "rb") as handle:
        return hashlib.sha256(handle.read()).hexdigest()


with open(GOLDEN) as _handle:
    _golden = json.load(_handle)


@pytest.mark.parametrize("scene", sorted(_golden["sha256"]))
def test_shipped_scene_traces_are_byte_identical_for_a_seed(scene, tmp_path):
    got = trace_hash(scene, _golden["seed"], _golden["until_s"], str(tmp_path / "trace.jsonl"))
    assert got == _golden["sha256"][scene]


def test_every_shipped_scene_has_a_golden_trace():
    assert sorted(_golden["sha256"]) == sorted(f for f in os.listdir(SCENES) if f.endswith(".yaml"))


if __name__ == "__main__" and sys.argv[1:] == ["--record"]:
    import tempfile

    with tempfile.TemporaryDirectory() as folder:
        hashes = {scene: trace_hash(scene, _golden["seed"], _golden["until_s"], os.path.join(folder, "t.jsonl"))
                  for scene in sorted(f for f in os.listdir(SCENES) if f.endswith(".yaml"))}
    with open(GOLDEN, "w") as handle:
        json.dump({**_golden, "sha256": hashes}, handle, indent=2)
        handle.write("\n")
