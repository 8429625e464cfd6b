"""Material presets: the fitted models of thesis tables 3.1-3.3 and hand-set materials.

Presets are plain JSON-able dicts in the format of :mod:`lobeview.materials.spec`; they are
validated like user materials (a test validates every one).

Fitted (thesis section 3.4.2; numbers copied from the tables, "albedo" is what the table
reports, see docs/guide.md "Presets" for how lobeview's own albedo compares):
  alanod-2000gs-1lobe / -2lobe  scattergloss aluminium, Table 3.1 (albedo 0.787 / 0.878)
  white-foil                    partly transmissive foil, Table 3.2 (refl. 0.807, trans. 0.093)
  miro5-1lobe / -2lobe          brushed anisotropic aluminium, Table 3.3 (albedo 0.815 / 0.944)

Hand-set (thesis model). With alpha = 0 the model darkens towards grazing like cos(theta_o); a
larger alpha restores the Fresnel-driven grazing rise of real glass and metal but breaks energy
conservation for wide lobes (thesis 3.3). Each preset uses the largest alpha (in steps of 0.05-0.1)
for which its directional albedo stays <= 1 for viewing angles up to 89.9 degrees (tested):
chrome 0.45, clear glass 0.5, lacquer 0.3, plastic 0.2, porcelain glaze 0.2, frosted glass 0.2.
  chrome         r0 = measured Cr F0 (Palik n, k -> linear sRGB, shared/assets/brdf), m = 0.01
  lacquer        red diffuse base under a clear coat: r0 = 0.04 (n = 1.5), m = 0.02, alpha = 0.3
                 for the grazing brightening of varnish the thesis shows (Fig. 3.4)
  plastic        blue diffuse + one r0 = 0.04 lobe, m = 0.12
  porcelain      white diffuse + sharp glaze lobe (m = 0.015) + soft sheen lobe (m = 0.2)
  clear-glass    thin pane: r0 = 0.08 (two air/glass interfaces at n = 1.5, each 0.04),
                 reflection and transmission lobes with m = 0.003
  frosted-glass  thin pane with m = 0.25 reflection and transmission lobes, r0 = 0.08
Microfacet / glTF examples:
  gold-ggx       GGX conductor, alpha 0.15, exact Fresnel with Au n, k at 650/550/450 nm
  brushed-steel-beckmann  anisotropic Beckmann conductor alpha (0.05, 0.3), Schlick r0 0.55
  gltf-red-plastic        glTF metallic-roughness, base (0.6, 0.05, 0.04), roughness 0.4
"""

from __future__ import annotations

CHROME_F0 = [0.6346, 0.6623, 0.7046]  # shared/assets/brdf/metal_F0_linear_srgb.csv, Cr
GOLD_ETA = [0.1678, 0.3504, 1.5085]  # Au.eta.spd at 650, 550, 450 nm
GOLD_K = [3.1378, 2.7141, 1.8788]  # Au.k.spd at 650, 550, 450 nm


def _lobe(k_name, k, mx, my, r0, alpha):
    return {k_name: k, "mx": mx, "my": my, "r0": r0, "alpha": alpha}


def _refl(ks, mx, my, r0, alpha):
    return _lobe("ks", ks, mx, my, r0, alpha)


def _trans(kt, mx, my, r0, alpha):
    return _lobe("kt", kt, mx, my, r0, alpha)


PRESETS: dict[str, dict] = {
    "alanod-2000gs-1lobe": {
        "model": "thesis",
        "description": "Alanod 2000GS scattergloss aluminium, 1 lobe (thesis Table 3.1)",
        "kd": 0.003,
        "lobes": [_refl(0.9, 0.11, 0.072, 0.89, 0.43)],
    },
    "alanod-2000gs-2lobe": {
        "model": "thesis",
        "description": "Alanod 2000GS scattergloss aluminium, 2 lobes (thesis Table 3.1)",
        "kd": 0.003,
        "lobes": [_refl(0.9, 0.11, 0.07, 0.87, 0.45), _refl(0.12, 0.25, 0.17, 0.89, 0.6)],
    },
    "white-foil": {
        "model": "thesis",
        "description": "White foil with a transmission lobe (thesis Table 3.2)",
        "kd": 0.76,
        "lobes": [_refl(0.78, 0.124, 0.136, 0.029, 0.5)],
        "transmission_lobes": [_trans(0.67, 0.25, 0.17, 0.75, 0.6)],
    },
    "miro5-1lobe": {
        "model": "thesis",
        "description": "Miro 5 brushed anisotropic aluminium, 1 lobe (thesis Table 3.3)",
        "kd": 0.003,
        "lobes": [_refl(0.98, 0.0068, 0.0297, 0.84, 0.49)],
    },
    "miro5-2lobe": {
        "model": "thesis",
        "description": "Miro 5 brushed anisotropic aluminium, 2 lobes (thesis Table 3.3)",
        "kd": 0.003,
        "lobes": [_refl(0.57, 0.0046, 0.0267, 0.94, 0.5), _refl(0.54, 0.013, 0.1199, 0.84, 0.38)],
    },
    "chrome": {
        "model": "thesis",
        "description": "Polished chrome: measured Cr F0, near-mirror lobe",
        "kd": 0.0,
        "lobes": [_refl(1.0, 0.01, 0.01, CHROME_F0, 0.45)],
    },
    "lacquer": {
        "model": "thesis",
        "description": "Red lacquered wood: diffuse base under a glossy clear coat",
        "kd": [0.32, 0.035, 0.03],
        "lobes": [_refl(1.0, 0.02, 0.02, 0.04, 0.3)],
    },
    "plastic": {
        "model": "thesis",
        "description": "Blue glossy plastic",
        "kd": [0.05, 0.15, 0.55],
        "lobes": [_refl(1.0, 0.12, 0.12, 0.04, 0.2)],
    },
    "porcelain": {
        "model": "thesis",
        "description": "Glazed white porcelain: sharp glaze + soft sheen",
        "kd": [0.78, 0.77, 0.74],
        "lobes": [_refl(1.0, 0.015, 0.015, 0.04, 0.2), _refl(0.25, 0.2, 0.2, 0.04, 0.0)],
    },
    "clear-glass": {
        "model": "thesis",
        "description": "Clear thin glass pane (two interfaces, r0 = 0.08)",
        "kd": 0.0,
        "lobes": [_refl(1.0, 0.003, 0.003, 0.08, 0.5)],
        "transmission_lobes": [_trans(1.0, 0.003, 0.003, 0.08, 0.5)],
    },
    "frosted-glass": {
        "model": "thesis",
        "description": "Frosted (acid-etched) thin glass pane",
        "kd": 0.0,
        "lobes": [_refl(1.0, 0.25, 0.25, 0.08, 0.2)],
        "transmission_lobes": [_trans(0.95, 0.25, 0.25, 0.08, 0.2)],
    },
    "gold-ggx": {
        "model": "microfacet",
        "description": "Gold, GGX, exact conductor Fresnel (Palik n, k)",
        "distribution": "ggx",
        "alpha": 0.15,
        "fresnel": {"type": "conductor", "eta": GOLD_ETA, "k": GOLD_K},
    },
    "brushed-steel-beckmann": {
        "model": "microfacet",
        "description": "Brushed steel, anisotropic Beckmann, Schlick Fresnel",
        "distribution": "beckmann",
        "alpha_u": 0.05,
        "alpha_v": 0.3,
        "fresnel": {"type": "schlick", "r0": 0.55},
    },
    "gltf-red-plastic": {
        "model": "gltf",
        "description": "glTF metallic-roughness red plastic",
        "base_color": [0.6, 0.05, 0.04],
        "metallic": 0.0,
        "roughness": 0.4,
    },
}

#: Values the thesis tables report for the fitted presets: reflectance ("Albedo"/"Refl.") and
#: transmittance ("Trans.").
THESIS_TABLE_ALBEDO = {
    "alanod-2000gs-1lobe": {"reflectance": 0.787},
    "alanod-2000gs-2lobe": {"reflectance": 0.878},
    "white-foil": {"reflectance": 0.807, "transmittance": 0.093},
    "miro5-1lobe": {"reflectance": 0.815},
    "miro5-2lobe": {"reflectance": 0.944},
}

#: Incidence angles (degrees) of the goniophotometer measurements the thesis fitted to
#: (captions of Fig. 3.11 / 3.17 and 3.14); the table albedos are compared with the mean
#: directional albedo over these angles.
THESIS_MEASURED_THETA_DEG = {
    "alanod-2000gs-1lobe": (0, 5, 20, 35, 50, 65),
    "alanod-2000gs-2lobe": (0, 5, 20, 35, 50, 65),
    "white-foil": (0, 5, 19, 33, 47, 61, 75),
    "miro5-1lobe": (0, 5, 20, 35, 50, 65),
    "miro5-2lobe": (0, 5, 20, 35, 50, 65),
}
