"""Material maths: what the library needs from a Blender material, and the defaults.

- Reflectance = Base Color, each channel clamped to [0, 0.999] (the library needs rho < 1 for
  the solution to converge).
- Blender's Emission Color x Emission Strength is a radiance L (W/m^2/sr); a Lambertian emitter's
  radiant exitance is E = pi x L, which is what the library takes.
- The per-object emitter multiplier scales E.
- A texture on Base Color (or a Diffuse BSDF's Color), on the emission colour or on the
  emission strength is read per face as its mean over the face (``addon/blender/textures.py``)
  where its node chain is readable; a strength from a Value node or a Math node of readable
  values is read at each frame (``addon/blender/materials.py``).
- What cannot be read (any other node chain on those inputs, a shader other than Principled
  BSDF, Diffuse BSDF or Emission, no material) uses ``DEFAULT_REFLECTANCE`` and no emission, and
  the bake reports it once.

Results go back the other way: the attribute holds outgoing radiance B / pi (scene-linear), so
an emitter shows L and a white wall under it shows rho x E / pi.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

DEFAULT_REFLECTANCE = (0.8, 0.8, 0.8)
MAX_REFLECTANCE = 0.999


def reflectance(base_color) -> tuple[float, float, float]:
    """Base Color (RGB or RGBA, scene-linear) to a reflectance the library accepts."""
    rgb = np.asarray(base_color, np.float64)[:3]
    rgb = np.where(np.isfinite(rgb), rgb, 0.0)
    return tuple(float(x) for x in np.clip(rgb, 0.0, MAX_REFLECTANCE))


def exitance(emission_color, strength: float, multiplier: float = 1.0) -> tuple[float, float, float]:
    """Emission Color x Strength (radiance) x multiplier to radiant exitance E = pi L."""
    rgb = np.asarray(emission_color, np.float64)[:3] * float(strength) * float(multiplier) * math.pi
    rgb = np.where(np.isfinite(rgb), rgb, 0.0)
    return tuple(float(x) for x in np.maximum(rgb, 0.0))


def radiance_from_radiosity(b: np.ndarray) -> np.ndarray:
    """Radiosity B (W/m^2) to the outgoing radiance B / pi stored in the colour attribute."""
    return np.asarray(b, np.float32) * np.float32(1.0 / math.pi)


@dataclass
class MaterialSpec:
    """One library material. ``problem`` says why a default was used, None if all was read."""

    name: str
    reflectance: tuple[float, float, float] = DEFAULT_REFLECTANCE
    emission: tuple[float, float, float] = (0.0, 0.0, 0.0)
    problem: str | None = None

    @property
    def emits(self) -> bool:
        return max(self.emission) > 0.0


@dataclass
class MaterialTable:
    """Library materials keyed by (material name, emitter multiplier); index = library index."""

    specs: list[MaterialSpec] = field(default_factory=list)
    index: dict = field(default_factory=dict)
    # Textures that could not be sampled on some object ("Mat (reason)"), each once.
    texture_problems: list[str] = field(default_factory=list)

    def add(self, key, spec_factory) -> int:
        if key not in self.index:
            self.index[key] = len(self.specs)
            self.specs.append(spec_factory())
        return self.index[key]

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(M,3) reflectance and (M,3) emission, float64."""
        if not self.specs:
            return np.zeros((0, 3)), np.zeros((0, 3))
        rho = np.array([s.reflectance for s in self.specs], np.float64)
        e = np.array([s.emission for s in self.specs], np.float64)
        return rho, e

    def problems(self) -> list[str]:
        # A chain both the material and the texture sampler failed to read is named once.
        lines = [f"{s.name} ({s.problem})" for s in self.specs if s.problem] + list(self.texture_problems)
        return list(dict.fromkeys(lines))
