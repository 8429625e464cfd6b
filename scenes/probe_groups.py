"""Shared probes (issue 18): nearby small objects with wide lobes are shaded from one cube map.

An object's cube map is rendered from its bounding-box centre without the object itself
(viewer/cube_bake.py). Objects whose lobes are wide enough that the lobe-width rule gives them a
small face (materials/lobe_spread.py ``lobe_width_face_size`` <= SHARED_PROBE_MAX_FACE out of the
default 256, whatever the chosen full size) gain little from a cube map of
their own when another such object stands close by: a group of them shares one cube map, rendered
from the centre of the group's bounding box and without any member, and every member looks it up
through its own reflection proxy with the probe's centre (shaders/incident.glsl PARALLAX), so the
room around the group is seen where it is.

What a member loses: the other members' reflections (they are left out of the probe, as each
object is left out of its own) and the view from its own centre where no proxy corrects the
offset. The rule limits both, without making them negligible (bench/probe_sharing.py: a shelf of
props, median member 1.5 % relative RMSE, small gold props up to 23 %), which is why sharing is an
option (``--shared-probes``, SceneRenderer(shared_probes=True)):

- only objects of similar size group (bounding radii within ``size_ratio``): a desk is not grouped
  with the sphere standing on it, whose main reflection it is;
- no member's bounding box holds another member's centre (walls around a room, a box around its
  contents: what encloses a probe is what it must see);
- complete linkage: every pair of members has centres closer than ``link`` x the sum of their
  bounding radii, so a group is compact (no chains along a shelf);
- at most ``max_members`` per group.

The renderer offers as candidates only objects that are neither emissive (the others would lose
the lamp) nor transmissive (a pane transmits what lies right behind it) nor planar reflectors.
The constants were chosen by the error they cause against per-object cube maps
(bench/probe_sharing.py, docs/guide.md, --shared-probes).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SHARED_PROBE_MAX_FACE = 64  # lobes this wide or wider (lobe-width face <= 64^2 of 256^2) may share
SHARED_PROBE_LINK = 2.0  # centre distance <= LINK x (r_i + r_j) for every pair of members
SHARED_PROBE_SIZE_RATIO = 2.0  # bounding radii of members within this ratio
SHARED_PROBE_MAX_MEMBERS = 8


@dataclass(frozen=True)
class ProbeGroup:
    members: tuple  # object indices; the first one holds the shared cube map
    box_min: np.ndarray  # the members' bounding box
    box_max: np.ndarray

    @property
    def owner(self) -> int:
        return self.members[0]

    @property
    def centre(self) -> np.ndarray:
        """Where the shared cube map is rendered from."""
        return (self.box_min + self.box_max) / 2.0


def group_probes(
    boxes: dict,
    link: float = SHARED_PROBE_LINK,
    size_ratio: float = SHARED_PROBE_SIZE_RATIO,
    max_members: int = SHARED_PROBE_MAX_MEMBERS,
) -> list[ProbeGroup]:
    """Groups of two or more candidates (object index -> (box_min, box_max), the objects whose
    lobes allow sharing) that share a probe, by the rule of the module docstring. Greedy in index
    order (deterministic): a candidate joins the first group whose every member it links with."""
    if link <= 0 or size_ratio < 1 or max_members < 2:
        raise ValueError(
            f"probe groups: need link > 0, size_ratio >= 1, max_members >= 2 (got {link}, {size_ratio}, {max_members})"
        )
    centres, radii, bounds = {}, {}, {}
    for index, (lo, hi) in boxes.items():
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        centres[index] = (lo + hi) / 2.0
        radii[index] = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-9)
        bounds[index] = (lo, hi)

    def holds(i: int, j: int) -> bool:
        lo, hi = bounds[i]
        return bool(np.all(centres[j] >= lo) and np.all(centres[j] <= hi))

    def linked(i: int, j: int) -> bool:
        small, large = sorted((radii[i], radii[j]))
        close = np.linalg.norm(centres[i] - centres[j]) <= link * (radii[i] + radii[j])
        return bool(close and large <= size_ratio * small and not holds(i, j) and not holds(j, i))

    groups: list[list[int]] = []
    for index in sorted(boxes):
        for group in groups:
            if len(group) < max_members and all(linked(index, other) for other in group):
                group.append(index)
                break
        else:
            groups.append([index])
    found = []
    for group in groups:
        if len(group) < 2:
            continue
        lows = np.array([np.asarray(boxes[i][0], np.float64) for i in group])
        highs = np.array([np.asarray(boxes[i][1], np.float64) for i in group])
        found.append(ProbeGroup(tuple(group), lows.min(axis=0), highs.max(axis=0)))
    return found
