"""Fuzzing the scene loader and validator: whatever the text, the only outcomes are a valid Scene or a
SceneError of one line (never another exception, a hang or unbounded memory).

Three sources of input: YAML-ish token soup (syntax, anchors, tags, odd numbers and characters),
mutations of the shipped scenes (so that most of the text is valid and the validator is reached),
and random trees of the scene's own keys dumped as YAML (values of every type in every place).
Bounded to seconds in CI; ``make fuzz`` (HILGATE_FUZZ=1) runs many more examples.
"""

import glob
import os

import yaml
from fuzzkit import examples
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hilgate.scene import (
    FLOW_KEYS, LINK_KEYS, TOP_KEYS, VEHICLE_KEYS, Scene, SceneError, load_scene_text,
)

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SCENES = {path: open(path, encoding="utf-8").read() for path in sorted(glob.glob(os.path.join(REPO, "scenes", "*.yaml")))}
SLOW_OK = [HealthCheck.too_slow, HealthCheck.data_too_large]

# No "plugins" or "cameras": the fuzzer must not import modules or open calibration files by chance.
WORDS = sorted(set(TOP_KEYS + LINK_KEYS + VEHICLE_KEYS + FLOW_KEYS) - {"plugins", "cameras"}) + [
    "static", "path", "waypoints", "start", "legs", "hold_s", "to", "speed_mps", "min_delay_s", "unit", "expr",
    "protocol", "none", "cs-aloha", "s-fama", "s100", "evologics-s2cr-7-17", "sim", "half", "full", "vl2b",
    "simple:20", "raw", "*", "bit", "byte", "packet", "d", "6e-13 * d^13.7", "rov0", "rov1", "rf", "acoustic",
    # the physical channel model (issue 16)
    "kind", "physical", "evologics-s2cr-18-34", "band_khz", "source_level_db", "level", "modulation", "bpsk",
    "bfsk", "coding_gain_db", "absorption", "thorp", "francois-garrison", "spreading", "collisions", "sinr",
    "capture_db", "noise_band", "centre", "noise_floor_db", "ph", "depth_m",
]
TOKENS = WORDS + [
    "\n", "\n  ", "\n    ", " ", ": ", ":", "- ", "[", "]", "{", "}", ", ", "&a ", "*a", "&b ", "*b", "<<: ", "? ",
    "!!int ", "!!str ", "!!float ", "!!timestamp ", "!!binary ", "!!map ", "!!set ", "!foo ", "!", "'", '"', "#",
    "x-", "|", ">", "~", "null", "true", "=", "0", "1", "-1", "2.5", "1e3", "1e400", "9" * 400, "0x1F", "0o17",
    "1:2:3", "2024-01-01", "2024-13-45", ".inf", "-.inf", ".nan", "\t", "\x01", "\x85", "\u2028", "\ufeff", "é",
    "\\", "%YAML 1.1\n", "---\n", "...\n", "\r\n",
]

yamlish = st.lists(st.one_of(st.sampled_from(TOKENS), st.text(max_size=4)), max_size=80).map("".join)


def outcome(text: str, file: str) -> None:
    """The only allowed outcomes: a Scene, or one line of SceneError."""
    try:
        scene = load_scene_text(text, file)
    except SceneError as exc:
        message = str(exc)
        assert "\n" not in message and len(message.splitlines()) == 1, repr(message)
        assert len(message) < 1200, len(message)
        return
    assert isinstance(scene, Scene)


@settings(max_examples=examples(150), deadline=None, suppress_health_check=SLOW_OK)
@given(yamlish)
def test_fuzz_yamlish_text(text):
    outcome(text, "fuzz.yaml")


@st.composite
def mutated_scene(draw):
    path = draw(st.sampled_from(sorted(SCENES)))
    text = SCENES[path]
    for _ in range(draw(st.integers(1, 4))):
        op = draw(st.sampled_from(["delete", "insert", "replace", "duplicate", "truncate", "swap"]))
        i = draw(st.integers(0, len(text)))
        j = min(len(text), i + draw(st.integers(0, 40)))
        if op == "delete":
            text = text[:i] + text[j:]
        elif op == "insert":
            text = text[:i] + draw(st.sampled_from(TOKENS)) + text[i:]
        elif op == "replace":
            text = text[:i] + draw(yamlish) + text[j:]
        elif op == "duplicate":
            text = text[:j] + text[i:j] + text[j:]
        elif op == "truncate":
            text = text[:i]
        else:
            lines = text.split("\n")
            a, b = draw(st.integers(0, len(lines) - 1)), draw(st.integers(0, len(lines) - 1))
            lines[a], lines[b] = lines[b], lines[a]
            text = "\n".join(lines)
    return path, text


@settings(max_examples=examples(60), deadline=None, suppress_health_check=SLOW_OK)
@given(mutated_scene())
def test_fuzz_mutated_shipped_scenes(case):
    path, text = case
    outcome(text, path)  # the real path: presets named relative to scenes/ resolve as they would


scalars = st.one_of(
    st.none(), st.booleans(), st.integers(-10, 300), st.integers(), st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from(WORDS), st.text(max_size=8), st.just(10 ** 400),
)
trees = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.sampled_from(WORDS), inner, max_size=5)),
    max_leaves=40,
)


@st.composite
def scene_tree(draw):
    """A scene-shaped document: the right top-level keys, random values below them."""
    doc = {"channels": draw(st.one_of(st.just({"rf": {"speed_mps": 2.25e7}}), trees)),
           "vehicles": draw(st.one_of(st.just({"rov0": {"pose": {"static": [0, 0, 0]}},
                                                "rov1": {"pose": {"static": [1, 0, 0]}}}), trees)),
           "links": draw(st.dictionaries(st.sampled_from(["rov0_rf", "rov1_rf", "bad id"]),
                                         st.one_of(st.dictionaries(st.sampled_from(LINK_KEYS), trees, max_size=6)
                                                   .map(lambda d: {"vehicle": "rov0", **d}), trees), max_size=3))}
    for key in draw(st.lists(st.sampled_from(["flows", "trace", "seed", "duration_s", "name"]), max_size=3)):
        doc[key] = draw(trees)
    return doc


@settings(max_examples=examples(60), deadline=None, suppress_health_check=SLOW_OK)
@given(scene_tree())
def test_fuzz_scene_shaped_trees(doc):
    outcome(yaml.safe_dump(doc, allow_unicode=True), "fuzz.yaml")
