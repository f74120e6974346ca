"""Scene files: the YAML reader that keeps file:line on every value, the checks, presets, plugins,
``--set`` overrides, the typed specs, and loading a scene whole (or, for a reload, in a worker
process).  ``from hilgate.scene import load_scene`` is the public way in.

One module per concern: :mod:`.yaml_nodes` (located YAML), :mod:`.checks` (value checkers, "did you
mean"), :mod:`.specs` (the typed result), :mod:`.presets`, :mod:`.overrides` (``--set``),
:mod:`.links` (with :mod:`.mac`), :mod:`.vehicles` (pose sources, cameras), :mod:`.flows`,
:mod:`.load` (the whole scene), :mod:`.plugins` and :mod:`.worker` (reloads in a child process).
"""

from .flow_spec import FLOW_KEYS
from .links import BACKENDS, LINK_KEYS
from .load import TOP_KEYS, load_scene, load_scene_text, scene_summary
from .presets import preset_names
from .specs import CameraSpec, LinkSpec, MacSpec, PoseSpec, Scene, VehicleSpec
from .vehicles import POSE_KINDS, VEHICLE_KEYS
from .yaml_nodes import SceneError

__all__ = [
    "BACKENDS", "FLOW_KEYS", "LINK_KEYS", "POSE_KINDS", "TOP_KEYS", "VEHICLE_KEYS", "CameraSpec", "LinkSpec",
    "MacSpec", "PoseSpec", "Scene", "SceneError", "VehicleSpec", "load_scene", "load_scene_text", "preset_names",
    "scene_summary",
]
