"""lobeview: real-time walkthrough viewer for light-mapped glTF scenes with glossy materials.

Sub-packages (see docs/architecture.md): ``materials`` (numpy BSDF references, lobe patterns, presets),
``scenes`` (glTF, lightmaps, environment maps), ``viewer`` (OpenGL renderer), ``app``
(command line and window). Dependencies point one way: app -> viewer -> materials/scenes.
"""

__version__ = "0.1.0"
