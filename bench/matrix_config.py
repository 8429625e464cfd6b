"""The default contents of the benchmark matrix: materials, methods, views, sweeps."""

from __future__ import annotations

from lobeview.core.paths import shared_assets_dir

#: material classes of the issue -> presets
MATERIAL_CLASSES = {
    "near-mirror": "chrome",
    "very glossy": "lacquer",
    "glossy": "alanod-2000gs-1lobe",
    "glossy GGX": "gold-ggx",
    "anisotropic": "miro5-2lobe",
    "transmissive": "frosted-glass",
}
QUICK_MATERIALS = ("chrome", "alanod-2000gs-1lobe", "frosted-glass")
FULL_METHODS = (
    "lobe-3",
    "lobe-5",
    "lobe-7",
    "lobe-11",
    "lobe-15",
    "lobe-19",
    "lobe-7+norm",
    "lobe-15+norm",
    "fis-8",
    "fis-16",
    "fis-32",
    "fis-64",
    "mc-16",
    "mc-64",
    "prefiltered",
    "prefiltered-lobe2d",
    "prefiltered-phong",
)
QUICK_METHODS = ("lobe-3", "lobe-7", "lobe-15", "fis-8", "fis-32", "mc-16", "prefiltered")
FULL_VIEWS = ("sphere/interior", "sphere/courtyard", "demo/table", "demo/overview")
QUICK_VIEWS = ("sphere/interior",)
SWEEP_BIASES = (-1.0, -0.5, 0.0, 0.5, 1.0, 1.5, 2.0)
SWEEP_METHODS = ("fis-16", "fis-64", "lobe-7", "lobe-15")
QUICK_SWEEP_BIASES = (-1.0, 0.0, 1.0)
QUICK_SWEEP_METHODS = ("fis-16", "lobe-7")
FPS_SAMPLES = (3, 5, 7, 9, 11, 13, 15, 17, 19)
QUICK_FPS_SAMPLES = (3, 7, 11, 19)
#: thesis table 4.1 (cube-map method, GTS 450, 1680x1050): samples -> (full, half) fps
THESIS_FPS = {3: (70, 95), 5: (52, 75), 7: (41, 60), 9: (35, 52), 11: (30, 43), 13: (26, 40), 15: (24, 35)}
THESIS_FPS.update({17: (22, 31), 19: (20, 28)})
SHARED_ASSETS = shared_assets_dir()  # None outside a checkout: sphere views fall back to built-in skies
SHARED_ENV_DIR = SHARED_ASSETS / "env" if SHARED_ASSETS is not None else None
SPHERE_ENVS = {
    "interior": ("blender_studiolights_1k/interior.exr", "builtin:studio"),
    "courtyard": ("blender_studiolights_1k/courtyard.exr", "builtin:sky"),
    "city": ("blender_studiolights_1k/city.exr", "builtin:overcast"),
}
PSNR_TARGETS = (40.0, 50.0)
