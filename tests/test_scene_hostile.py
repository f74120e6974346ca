"""A scene is input from outside (issue 10 items 5-7, issue 11 items 5-6): presets only from allowed
places, plugins only when listed, a YAML loader that answers every hostile file with one line, and
paths taken relative to the scene's file."""

import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from hilgate.models.expr import ExprError, compile_expression
from hilgate.scene import SceneError, load_scene, load_scene_text

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
EXAMPLE_MAC = os.path.join(REPO, "tests", "example_mac.py")

BASE = ("channels: {ac: {speed_mps: 1500}}\n"
        "vehicles: {a: {pose: {static: [0, 0, 0]}}, b: {pose: {static: [10, 0, 0]}}}\n"
        "links:\n"
        "  x: {vehicle: a}\n"
        "  y: {vehicle: b}\n")


def one_line(error: SceneError) -> str:
    text = str(error)
    assert "\n" not in text and len(text.splitlines()) == 1, repr(text)
    assert len(text) < 1200, len(text)
    return text


def scene_error(text: str, file: str = "scene.yaml", **kw) -> SceneError:
    with pytest.raises(SceneError) as info:
        load_scene_text(text, file, **kw)
    one_line(info.value)
    return info.value


def check(*args, cwd=None, limit_mb=None, timeout=120):
    """``python -m hilgate ARGS`` (exit status, stdout, stderr); ``limit_mb`` caps its address space."""
    preexec = None
    if limit_mb:
        def preexec():
            import resource
            resource.setrlimit(resource.RLIMIT_AS, (limit_mb << 20, limit_mb << 20))
    env = dict(os.environ, PYTHONPATH=REPO)
    result = subprocess.run([sys.executable, "-m", "hilgate", *args], capture_output=True, text=True, cwd=cwd,
                            timeout=timeout, preexec_fn=preexec, env=env)
    return result.returncode, result.stdout, result.stderr


def write_scene(folder, link_extra: str = "", top_extra: str = "", name: str = "scene.yaml") -> str:
    os.makedirs(folder, exist_ok=True)
    path = os.path.join(folder, name)
    text = BASE.replace("x: {vehicle: a}", "x: {vehicle: a" + link_extra + "}") + top_extra
    with open(path, "w") as handle:
        handle.write(text)
    return path


# -- presets (issue 10 item 5) --------------------------------------------------------------------


@pytest.fixture
def secret(tmp_path):
    """A readable YAML file outside the scene's directory, whose content must never be echoed."""
    other = tmp_path / "other"
    other.mkdir()
    path = other / "secret.yaml"
    path.write_text("root: SECRET-hunter2\n")
    return str(path)


@pytest.mark.parametrize("model", ["{secret}", "../other/secret.yaml", "/etc/passwd", "/etc/shadow", "/dev/zero",
                                   "/dev/stdin", "/proc/self/environ", "../other/secret.yml"])
def test_preset_outside_the_allowed_directories_is_refused_without_opening_it(tmp_path, secret, model):
    scene = write_scene(tmp_path / "scene", f", model: {json.dumps(model.format(secret=secret))}")
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    text = one_line(info.value)
    assert info.value.path == "links.x.model" and info.value.line == 4, text
    assert "SECRET" not in text and "root:" not in text


def test_preset_symlinks_out_of_the_scene_directory_are_refused(tmp_path, secret):
    folder = tmp_path / "scene"
    folder.mkdir()
    os.symlink(secret, folder / "inside.yaml")
    os.symlink("/dev/zero", folder / "zero.yaml")
    for name in ("inside.yaml", "zero.yaml"):
        with pytest.raises(SceneError) as info:
            load_scene(write_scene(folder, f", model: {name}"))
        assert "SECRET" not in one_line(info.value) and info.value.path == "links.x.model"


def test_preset_that_is_not_a_regular_file_fails_check_at_once(tmp_path):
    folder = tmp_path / "scene"
    folder.mkdir()
    os.mkfifo(folder / "fifo.yaml")  # nobody writes: opening it for reading would wait forever
    (folder / "dir.yaml").mkdir()
    for name in ("fifo.yaml", "dir.yaml"):
        status, out, err = check("check", write_scene(folder, f", model: {name}"), timeout=60)
        assert status == 2 and "Traceback" not in err, err
        assert "scene.yaml:4: links.x.model: " in err and "regular file" in err, err


def test_oversized_preset_is_refused(tmp_path):
    folder = tmp_path / "scene"
    folder.mkdir()
    (folder / "big.yaml").write_text("bitrate_bps: 1900\n" + "# padding\n" * 10_000)
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(folder, ", model: big.yaml"))
    assert "larger than" in one_line(info.value) and info.value.path == "links.x.model"


@pytest.mark.parametrize("name", ["x" * 300, "x" * 300 + ".yaml", "a/" * 2000 + "b.yaml", "s100\0.yaml", "s100\n"])
def test_absurd_model_names_are_scene_errors(tmp_path, name):
    scene = write_scene(tmp_path, f", model: {json.dumps(name)}")
    with pytest.raises(SceneError) as info:
        load_scene(scene)
    assert info.value.path == "links.x.model" and info.value.line == 4, one_line(info.value)


def test_a_300_character_model_name_exits_2(tmp_path):
    status, _, err = check("check", write_scene(tmp_path, ", model: " + "x" * 300))
    assert status == 2 and "links.x.model" in err and "Traceback" not in err, err


def test_presets_in_the_scene_directory_and_in_preset_dirs(tmp_path):
    folder = tmp_path / "scene"
    (folder / "presets").mkdir(parents=True)
    (folder / "presets" / "mine.yml").write_text("bitrate_bps: 1234\n")
    scene = load_scene(write_scene(folder, ", model: presets/mine.yml"))
    assert scene.links["x"].params.bitrate_bps == 1234
    shared = tmp_path / "shared"
    shared.mkdir()
    (shared / "lab.yaml").write_text("bitrate_bps: 4321\n")
    path = write_scene(folder, f", model: {shared / 'lab.yaml'}")
    with pytest.raises(SceneError, match="outside"):
        load_scene(path)
    assert load_scene(path, preset_dirs=[str(shared)]).links["x"].params.bitrate_bps == 4321
    status, out, err = check("check", path, "--preset-dir", str(shared))
    assert status == 0 and "ok" in out, err


def test_packaged_preset_names_still_work():
    scene = load_scene_text(BASE.replace("{vehicle: a}", "{vehicle: a, model: s100}"), "scene.yaml")
    assert scene.links["x"].params.bitrate_bps == 1800


# -- plugins (issue 10 item 6) --------------------------------------------------------------------


def _probe_module(folder, name: str) -> str:
    """A module that leaves a marker file when it is imported."""
    marker = os.path.join(str(folder), name + ".imported")
    with open(os.path.join(str(folder), name + ".py"), "w") as handle:
        handle.write(f"open({marker!r}, 'w').close()\n")
    return marker


def test_a_mac_from_a_module_that_is_not_listed_imports_nothing(tmp_path, monkeypatch):
    marker = _probe_module(tmp_path, "hilgate_probe_unlisted")
    monkeypatch.syspath_prepend(str(tmp_path))
    error = scene_error(BASE.replace("{vehicle: a}", '{vehicle: a, mac: {protocol: "hilgate_probe_unlisted:Mac"}}'))
    assert error.path == "links.x.mac.protocol" and "plugins" in error.message
    assert not os.path.exists(marker) and "hilgate_probe_unlisted" not in sys.modules


def test_check_imports_nothing_it_was_not_told_to(tmp_path):
    status, out, err = check("check", write_scene(tmp_path, ', mac: {protocol: "this:X"}'))
    assert status == 2 and "Beautiful is better" not in out + err, out + err
    # a module in the working directory is never picked up: neither named by a MAC nor as a plugin
    marker = _probe_module(tmp_path, "evil")
    status, _, err = check("check", write_scene(tmp_path, ', mac: {protocol: "evil:Mac"}'), cwd=str(tmp_path))
    assert status == 2 and not os.path.exists(marker), err
    status, _, err = check("check", write_scene(tmp_path, "", "plugins: [evil]\n"), cwd=str(tmp_path))
    assert status == 2 and "plugins[0]" in err and not os.path.exists(marker), err


def test_plugin_file_listed_in_the_scene_provides_a_mac(tmp_path):
    folder = tmp_path / "scene"
    (folder / "macs").mkdir(parents=True)
    shutil.copy(EXAMPLE_MAC, folder / "macs" / "tdma.py")
    path_before = list(sys.path)
    for protocol, params in (("tdma", ", slot_s: 0.5"), ("tdma:Tdma", ""), ("tdma:Tdma", ", slots: 2")):
        scene = load_scene(write_scene(folder, f", mac: {{protocol: {json.dumps(protocol)}{params}}}",
                                       "plugins: [macs/tdma.py]\n"))
        mac = scene.links["x"].mac.build()
        assert type(mac).__name__ == "Tdma" and scene.links["y"].mac.protocol == "none"
    assert sys.path == path_before and "tdma" not in sys.modules
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(folder, ", mac: {protocol: tdma, slot_s: 0}", "plugins: [macs/tdma.py]\n"))
    assert info.value.path == "links.x.mac.slot_s" and info.value.line == 4
    # the scene's plugins are relative to the scene, wherever hilgate runs
    status, out, err = check("check", write_scene(folder, ", mac: tdma", "plugins: [macs/tdma.py]\n"), cwd="/")
    assert status == 0 and "mac tdma" in out, err


def test_plugin_from_the_command_line_and_as_a_module(tmp_path):
    path = write_scene(tmp_path, ', mac: {protocol: "example_mac:Tdma", slots: 3}')
    with pytest.raises(SceneError, match="plugins"):
        load_scene(path)
    assert load_scene(path, plugins=[EXAMPLE_MAC]).links["x"].mac.params == (("slot_s", 1.0), ("slots", 3))
    status, out, err = check("check", path, "--plugin", EXAMPLE_MAC)
    assert status == 0 and "mac example_mac:Tdma" in out, err
    # an importable module by name (tests/ is on sys.path in the test run)
    by_name = write_scene(tmp_path, ", mac: tdma", "plugins: [example_mac]\n", name="by-name.yaml")
    assert type(load_scene(by_name).links["x"].mac.build()).__name__ == "Tdma"


@pytest.mark.parametrize("entry,words", [
    ("missing.py", "cannot load plugin"),
    ("notes.txt", "a .py file"),
    ("'no-such module'", "not a module name"),
    ("hilgate_no_such_module_xyz", "cannot load plugin"),
    ("broken.py", "ZeroDivisionError"),
    ("{a: 1}", "must be a non-empty text"),
])
def test_plugin_errors_name_the_entry(tmp_path, entry, words):
    (tmp_path / "broken.py").write_text("1 / 0\n")
    (tmp_path / "notes.txt").write_text("")
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(tmp_path, "", f"plugins:\n  - {entry}\n"))
    text = one_line(info.value)
    assert info.value.path == "plugins[0]" and info.value.line == 7 and words in text, text


def test_unknown_protocol_names_what_plugins_provide(tmp_path):
    shutil.copy(EXAMPLE_MAC, tmp_path / "tdma.py")
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(tmp_path, ", mac: tdmaa", "plugins: [tdma.py]\n"))
    assert "tdma" in info.value.message and "cs-aloha" in info.value.message
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(tmp_path, ', mac: "tdma:Nope"', "plugins: [tdma.py]\n"))
    assert info.value.path == "links.x.mac.protocol" and "Nope" in info.value.message
    with pytest.raises(SceneError) as info:
        load_scene(write_scene(tmp_path, ', mac: "tdma:Param"', "plugins: [tdma.py]\n"))
    assert "not a MAC" in info.value.message


# -- the YAML loader (issue 10 item 7) ------------------------------------------------------------


def nested_blocks(levels: int) -> str:
    return "x-deep:\n" + "".join(" " * (i + 1) + f"k{i}:\n" for i in range(levels)) + " " * (levels + 1) + "1\n"


def laughs(width: int = 9, depth: int = 9) -> str:
    lines = ["x-l0: &l0 [lol]"]
    for i in range(1, depth + 1):
        lines.append(f"x-l{i}: &l{i} [" + ", ".join([f"*l{i - 1}"] * width) + "]")
    return "\n".join(lines) + "\n"


HOSTILE = {
    "recursive list": ("x-r: &r [*r]\n" + BASE, 1, "alias"),
    "recursive map": ("x-r: &x {a: *x}\n" + BASE, 1, "alias"),
    "recursive merge": ("x-r: &x {<<: *x}\n" + BASE, 1, "alias"),
    "billion laughs": (laughs() + BASE, 0, "expand"),
    "laughs by merge": ("x-a: &a {k: 1}\n" + "".join(
        f"x-m{i}: &m{i} {{<<: [" + ", ".join([f"*{'a' if i == 0 else f'm{i - 1}'}"] * 9) + "]}\n"
        for i in range(9)) + BASE, 0, "expand"),
    "deep flow": ("x-d: " + "[" * 5000 + "]" * 5000 + "\n" + BASE, 1, "deeper"),
    "deep flow map": ("x-d: " + "{a: " * 3000 + "1" + "}" * 3000 + "\n" + BASE, 1, "deeper"),
    "deep blocks": (nested_blocks(1000) + BASE, 0, "deeper"),
    "deep block lists": ("x-deep:\n" + "- " * 3000 + "1\n" + BASE, 0, "deeper"),
    "deep aliases": ("".join(f"x-{i}: &a{i} [{'*a' + str(i - 1) if i else 1}]\n" for i in range(200)) + BASE,
                     0, "deeper"),
    "control character": ("x-c: \x01\n" + BASE, 1, "control character"),
    "escape character": (BASE + "name: \x1b[31mred\n", 6, "control character"),
    "big integer": (BASE.replace("1500", "9" * 400), 1, "too large"),
    "big integer in a vector": (BASE.replace("[0, 0, 0]", "[0, 0, " + "9" * 400 + "]"), 2, "too large"),
    "big integer expression": (BASE.replace("{vehicle: a}", "{vehicle: a, error: {expr: " + "9" * 400 + "}}"),
                               4, "too large"),
    "huge integer": ("x-t: " + "9" * 5000 + "\n" + BASE, 1, "number"),
    "sexagesimal monster": ("x-t: 1" + ":1" * 50_000 + "\n" + BASE, 1, "number"),
    "huge packet class": (BASE.replace("{vehicle: a}", "{vehicle: a, packet: 'simple:" + "9" * 5000 + "'}"),
                          4, "simple:N"),
    "bad timestamp": ("x-t: !!timestamp not-a-date\n" + BASE, 1, "timestamp"),
    "impossible date": ("x-t: !!timestamp 2024-13-45\n" + BASE, 1, "timestamp"),
    "empty int": ("x-t: !!int\n" + BASE, 1, "!!int"),
    "empty float": ("x-t: !!float ''\n" + BASE, 1, "!!float"),
    "unknown tag": ("x-t: !foo bar\n" + BASE, 1, "!foo"),
    "python tag": ("x-t: !!python/object/apply:os.system [echo hi]\n" + BASE, 1, "tag"),
    "tagged mapping": ("x-t: !foo {a: 1}\n" + BASE, 1, "!foo"),
    "bad base64": ("x-t: !!binary 'QQ'\n" + BASE, 1, "binary"),
    "undefined alias": ("x-t: *" + "n" * 5000 + "\n" + BASE, 1, "alias"),
    "huge key": (BASE + "? " + "k" * 100_000 + "\n: 1\n", 6, "unknown key"),
    "newline in a key": (BASE + '"a\\nb\\u2028c": 1\n', 6, "unknown key"),
    "tab indentation": (BASE + "vehicles:\n\tb: 1\n", 7, "YAML"),
}


@pytest.mark.parametrize("name", list(HOSTILE))
def test_hostile_yaml_is_one_line_with_file_and_line(name):
    text, line, words = HOSTILE[name]
    error = scene_error(text)
    assert error.file == "scene.yaml", str(error)
    if line:
        assert error.line == line, str(error)
    assert words in str(error), str(error)


def test_merge_keys_let_the_mapping_override_what_it_merges():
    text = BASE.replace("links:", "x-m: &m {vehicle: a, bitrate_bps: 5, tx_delay_s: 1}\nlinks:").replace(
        "x: {vehicle: a}", "x: {<<: *m, bitrate_bps: 7}")
    params = load_scene_text(text, "scene.yaml").links["x"].params
    assert params.bitrate_bps == 7 and params.tx_delay_s == 1
    assert "duplicate key" in str(scene_error(text.replace("bitrate_bps: 7}", "bitrate_bps: 7, bitrate_bps: 8}")))


def test_files_over_the_size_limit_are_refused_before_reading(tmp_path):
    big = tmp_path / "big.yaml"
    with open(big, "wb") as handle:  # sparse: reading it would take gigabytes
        handle.truncate(4 << 30)
    status, _, err = check("check", str(big), limit_mb=400)
    assert status == 2 and f"{big}: " in err and "larger than" in err and "Traceback" not in err, err
    with pytest.raises(SceneError, match="larger than"):
        load_scene_text("# " + "x" * (2 << 20) + "\n" + BASE, "scene.yaml")
    status, _, err = check("check", "/dev/zero", limit_mb=400)
    assert status == 2 and "regular file" in err, err


def test_hostile_scenes_stay_within_bounded_memory(tmp_path):
    """Every hostile case in one process whose address space is capped: only SceneErrors come out."""
    script = textwrap.dedent("""
        import json, sys
        sys.path.insert(0, sys.argv[1])
        from test_scene_hostile import HOSTILE
        from hilgate.scene import SceneError, load_scene_text
        for name, (text, _, _) in HOSTILE.items():
            try:
                load_scene_text(text, "scene.yaml")
                print(json.dumps([name, "loaded"]))
            except SceneError as exc:
                print(json.dumps([name, "SceneError"]))
    """)
    def limit():
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (400 << 20, 400 << 20))
    result = subprocess.run([sys.executable, "-c", script, os.path.join(REPO, "tests")], capture_output=True,
                            text=True, preexec_fn=limit, timeout=600, env=dict(os.environ, PYTHONPATH=REPO))
    outcomes = dict(json.loads(line) for line in result.stdout.splitlines())
    assert result.returncode == 0, result.stderr[-2000:]
    assert outcomes == {name: "SceneError" for name in HOSTILE}


def test_set_values_are_read_with_the_same_limits():
    flow_laughs = "[" + ", ".join(["&l0 [lol]"] + [f"&l{i} [" + ", ".join([f"*l{i - 1}"] * 9) + "]"
                                                  for i in range(1, 10)]) + "]"
    for value in ("&a [*a]", "[" * 5000 + "]" * 5000, flow_laughs):
        try:
            load_scene_text(BASE, "scene.yaml", [f"x-t={value}"])
        except SceneError as exc:
            one_line(exc)
    with pytest.raises(SceneError) as info:
        load_scene_text(BASE, "scene.yaml", [".".join(["a"] * 5000) + "=1"])
    one_line(info.value)


def test_overflowing_numbers_in_expressions_are_expression_errors():
    with pytest.raises(ExprError, match="too large"):
        compile_expression(10 ** 400)
    assert compile_expression(10 ** 300).constant == 1e300


# -- paths relative to the scene (issue 11 item 5) ------------------------------------------------

CALIBRATION = ("image_width: 640\nimage_height: 480\n"
               "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [834.0, 0.0, 320.0, 0.0, 834.0, 240.0, 0.0, 0.0, 1.0]\n"
               "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.0, 0.0, 0.0, 0.0, 0.0]\n")


def camera_scene(calibration: str, source: str = "0") -> str:
    return (BASE.replace("a: {pose: {static: [0, 0, 0]}}", "a: {pose: {aruco: {camera: tank, marker: 7}}}")
            + f"cameras:\n  tank:\n    source: {source}\n    calibration: {calibration}\n"
              "    marker_length_m: 0.15\n    fixed: {position: [0, 0, 0]}\n")


def test_paths_in_a_scene_are_relative_to_its_file(tmp_path, monkeypatch):
    folder = tmp_path / "lab"
    folder.mkdir()
    (folder / "cal.yaml").write_text(CALIBRATION)
    text = camera_scene("cal.yaml", "videos/run1.mp4").replace(
        "x: {vehicle: a}", "x: {vehicle: a, emulate: {protocol: s100, pty: ttyS100}}") + "trace: {file: out/t.jsonl}\n"
    (folder / "scene.yaml").write_text(text)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    scene = load_scene(str(folder / "scene.yaml"))
    assert scene.trace_file == str(folder / "out" / "t.jsonl")
    assert scene.cameras["tank"].calibration == str(folder / "cal.yaml")
    assert scene.cameras["tank"].source == str(folder / "videos" / "run1.mp4")
    assert dict(scene.links["x"].emulate)["pty"] == str(folder / "ttyS100")
    # relative to the scene even when the scene is named by a relative path
    monkeypatch.chdir(tmp_path)
    assert load_scene("lab/scene.yaml").trace_file == str(folder / "out" / "t.jsonl")
    # a value given with --set is the user's, on the command line: relative to the working directory
    scene = load_scene(str(folder / "scene.yaml"), ['links.x.emulate={"protocol": "s100", "pty": "here"}',
                                                    "trace.file=t2.jsonl"])
    assert dict(scene.links["x"].emulate)["pty"] == str(tmp_path / "here")
    assert scene.trace_file == str(tmp_path / "t2.jsonl")
    # absolute paths, device numbers and stream URLs stay as they are
    (folder / "urls.yaml").write_text(camera_scene(str(folder / "cal.yaml"), '"rtsp://cam.local/s"'))
    assert load_scene(str(folder / "urls.yaml")).cameras["tank"].source == "rtsp://cam.local/s"


@pytest.mark.parametrize("setup,words", [
    (lambda d: None, "does not exist"),
    (lambda d: (d / "cal.yaml").write_text("%YAML:1.0\n---\nimage_width: 640\n"), "no camera_matrix"),
    (lambda d: (d / "cal.yaml").write_text("this is : : not [ yaml\n"), "cal.yaml"),
    (lambda d: (d / "cal.yaml").mkdir(), "regular file"),
    (lambda d: os.mkfifo(d / "cal.yaml"), "regular file"),
    (lambda d: (d / "cal.yaml").write_text(CALIBRATION + "#" * (2 << 20)), "larger than"),
])
def test_camera_calibration_is_checked_when_the_scene_loads(tmp_path, setup, words):
    setup(tmp_path)
    (tmp_path / "scene.yaml").write_text(camera_scene("cal.yaml"))
    with pytest.raises(SceneError) as info:
        load_scene(str(tmp_path / "scene.yaml"))
    text = one_line(info.value)
    assert info.value.path == "cameras.tank.calibration" and info.value.line == 9 and words in text, text


def test_missing_calibration_fails_check_with_exit_2(tmp_path):
    (tmp_path / "scene.yaml").write_text(camera_scene("nope.yaml"))
    status, _, err = check("check", str(tmp_path / "scene.yaml"))
    assert status == 2 and "scene.yaml:9: cameras.tank.calibration: " in err and "Traceback" not in err, err
    (tmp_path / "nope.yaml").write_text(CALIBRATION)
    status, out, err = check("check", str(tmp_path / "scene.yaml"), cwd="/")
    assert status == 0, err


def test_marker_ids_are_plain_digits(tmp_path):
    (tmp_path / "cal.yaml").write_text(CALIBRATION)
    text = camera_scene("cal.yaml").replace("fixed: {position: [0, 0, 0]}", "onboard: {vehicle: a}\n"
                                            "    map: {\"\\u00b2\": {position: [0, 0, 0]}}")
    text = text.replace("{aruco: {camera: tank, marker: 7}}", "{aruco: {camera: tank}}")
    (tmp_path / "scene.yaml").write_text(text)
    with pytest.raises(SceneError) as info:
        load_scene(str(tmp_path / "scene.yaml"))
    assert "marker ids" in one_line(info.value)


# -- serial ports (issue 11 item 6) ---------------------------------------------------------------


def test_port_urls_are_checked_when_the_scene_loads(tmp_path):
    link = ", backend: s100, port: {port}"
    for port in ('"nosuch://x"', '""'):
        with pytest.raises(SceneError) as info:
            load_scene(write_scene(tmp_path, link.format(port=port)))
        assert info.value.path == "links.x.port" and info.value.line == 4, one_line(info.value)
    scene = load_scene(write_scene(tmp_path, link.format(port="ttyEMU0")))
    assert dict(scene.links["x"].options)["port"] == str(tmp_path / "ttyEMU0")
    scene = load_scene(write_scene(tmp_path, link.format(port='"socket://localhost:9200"')))
    assert dict(scene.links["x"].options)["port"] == "socket://localhost:9200"


def test_a_link_id_with_a_trailing_newline_is_refused():
    error = scene_error(BASE.replace("  y: {vehicle: b}\n", '  "y\\n": {vehicle: b}\n'))
    assert "POSIX queues" in error.message and error.line == 5
