"""The one model difference between lobeview's microfacet lobes and Mitsuba 3's roughconductor
(bench/mitsuba.py): the shadowing-masking term. lobeview uses the height-correlated Smith term
G2 = 1 / (1 + Lambda(wi) + Lambda(wo)) (materials/microfacet.py, as glTF does), Mitsuba 3 the
separable product G1(wi) G1(wo) (its microfacet.h "Smith's separable shadowing-masking
approximation"). G2 >= G1 G1, the more so the more grazing: on GGX alpha 0.5 under the courtyard
capture lobeview's reference is 9 % brighter than Mitsuba on the sphere's outer tenth and 3 % on
the next, which made its "model floor" 7.2 % where the narrower lobes had 1.5 %.

:func:`separable_smith_ratio` estimates, per shading point, the reflected radiance with G2 over
the same with G1 G1 from one set of half-vector samples (pdf D cos(theta_m), materials/
microfacet.py half_vector_from_xi: GGX and Beckmann), so Mitsuba's image times this ratio is what
Mitsuba would render with lobeview's term."""

from __future__ import annotations

import numpy as np

from lobeview.scenes.self_visibility import horizon_frame

CHUNK = 128  # shading points per batch of samples (memory: CHUNK x samples x 3 doubles a few times)


def tangent_frames(normals: np.ndarray) -> np.ndarray:
    """(n, 3, 3) orthonormal frames whose rows are tangent, bitangent, normal (the tangents of
    scenes/self_visibility.py horizon_frame: any will do for an isotropic lobe)."""
    normals = normals / np.linalg.norm(normals, axis=-1, keepdims=True)
    tangents, bitangents = horizon_frame(normals)
    return np.stack([tangents, bitangents, normals], axis=1)


def separable_smith_ratio(
    environment, distribution, normals: np.ndarray, views: np.ndarray, samples: int = 1024, seed: int = 0
) -> np.ndarray:
    """(n, 3) per shading point and colour channel: the lobe's reflected radiance of
    ``environment`` (scenes/envmap.py EnvironmentMap, read in world directions) with the
    height-correlated Smith term over the same with the separable one, for an isotropic
    ``distribution`` (materials/microfacet.py MicrofacetDistribution; the frames' tangents are
    arbitrary) at world ``normals`` seen from world unit ``views`` (towards the eye). No Fresnel
    (it cancels). 1 where the view is below the surface or no sample leaves above it."""
    if distribution.alpha_x != distribution.alpha_y:
        raise ValueError("separable_smith_ratio: isotropic lobes only (the frames' tangents are arbitrary)")
    rng = np.random.default_rng(seed)
    normals, views = np.asarray(normals, dtype=np.float64), np.asarray(views, dtype=np.float64)
    out = np.ones((len(normals), 3))
    for start in range(0, len(normals), CHUNK):
        frames = tangent_frames(normals[start : start + CHUNK])
        wo = np.einsum("nij,nj->ni", frames, views[start : start + CHUNK])
        count = len(wo)
        wo_samples = np.broadcast_to(wo[:, None, :], (count, samples, 3)).reshape(-1, 3)
        u = rng.random((count * samples, 2))
        wm = distribution.half_vector_from_xi(1.0 - u[:, 0], u[:, 1])  # pdf D(wm) cos(theta_m)
        wo_m = np.sum(wm * wo_samples, axis=-1)
        wi = 2.0 * wo_m[:, None] * wm - wo_samples
        above = (wi[:, 2] > 0.0) & (wo_samples[:, 2] > 0.0) & (wo_m > 0.0)
        radiance = environment.lookup(np.einsum("nsj,nji->nsi", wi.reshape(count, samples, 3), frames))
        radiance = radiance.reshape(count * samples, 3)
        # f cos_i / pdf = G (wo . wm) / (cos_o cos_m): the D and the reflection's Jacobian cancel,
        # cos_o is common to both terms
        weight = np.where(above, wo_m / np.maximum(wm[:, 2], 1e-300), 0.0)
        with np.errstate(invalid="ignore"):
            correlated = np.where(above, weight * distribution.G(wi, wo_samples), 0.0)
            separable = np.where(above, weight * distribution.G1(wi) * distribution.G1(wo_samples), 0.0)
        numerator = (radiance * correlated[:, None]).reshape(count, samples, 3).sum(axis=1)
        denominator = (radiance * separable[:, None]).reshape(count, samples, 3).sum(axis=1)
        ratio = np.divide(numerator, denominator, out=np.ones_like(numerator), where=denominator > 0.0)
        out[start : start + count] = ratio
    return out


def sphere_points(size: int, camera, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For (row, column) ``pixels`` of a square ``size`` frame of the unit sphere at the origin
    seen by ``camera`` (eye, target, up, vertical fov in degrees; bench/mitsuba.py CAMERA):
    (hit, normals, views) at the pixel centres; ``hit`` False where the centre's ray misses."""
    eye, target, up, fov = (np.asarray(camera[0], float), np.asarray(camera[1], float),
                            np.asarray(camera[2], float), float(camera[3]))  # fmt: skip
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    true_up = np.cross(right, forward)
    half = np.tan(np.radians(fov) / 2.0)
    rows, columns = pixels[:, 0], pixels[:, 1]
    x = ((columns + 0.5) / size * 2.0 - 1.0) * half
    y = (1.0 - (rows + 0.5) / size * 2.0) * half
    directions = forward + x[:, None] * right + y[:, None] * true_up
    directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
    b = directions @ eye
    disc = b * b - (eye @ eye - 1.0)
    hit = disc > 0.0
    t = -b - np.sqrt(np.maximum(disc, 0.0))
    normals = eye + t[:, None] * directions
    normals /= np.linalg.norm(normals, axis=-1, keepdims=True)
    return hit, normals, -directions


def smith_matched(
    truth: np.ndarray, environment, distribution, camera, mask: np.ndarray, samples: int = 512, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(Mitsuba's ``truth`` as it would be with lobeview's Smith term, the pixels to compare it
    on): ``truth`` times separable_smith_ratio at each pixel centre of ``mask`` (the square frame
    of bench/mitsuba.py's preview sphere), and ``mask`` without its 2 outer pixel rings, where the
    box-filtered pixels mix the background across two different silhouettes (Mitsuba's analytic
    sphere, lobeview's triangulated one)."""
    from scipy.ndimage import binary_erosion

    size = truth.shape[0]
    interior = binary_erosion(mask, iterations=2)
    pixels = np.argwhere(interior)
    hit, normals, views = sphere_points(size, camera, pixels)
    ratios = np.ones((len(pixels), 3))
    ratios[hit] = separable_smith_ratio(environment, distribution, normals[hit], views[hit], samples, seed)
    matched = np.array(truth, dtype=np.float64, copy=True)
    matched[pixels[:, 0], pixels[:, 1]] *= ratios
    return matched, interior
