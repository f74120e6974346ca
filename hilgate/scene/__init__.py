"""Scene files: the YAML reader that keeps file:line on every value, the checks, presets, plugins,
``--set`` overrides, the typed specs, and loading a scene whole (or, for a reload, in a worker
process).  ``from hilgate.scene import load_scene`` is the public way in."""

from .load import (
    BACKENDS, FLOW_KEYS, LINK_KEYS, POSE_KINDS, TOP_KEYS, VEHICLE_KEYS, CameraSpec, LinkSpec, MacSpec, PoseSpec,
    Scene, SceneError, VehicleSpec, load_scene, load_scene_text, preset_names, scene_summary,
)

__all__ = [
    "BACKENDS", "FLOW_KEYS", "LINK_KEYS", "POSE_KINDS", "TOP_KEYS", "VEHICLE_KEYS", "CameraSpec", "LinkSpec",
    "MacSpec", "PoseSpec", "Scene", "SceneError", "VehicleSpec", "load_scene", "load_scene_text", "preset_names",
    "scene_summary",
]
