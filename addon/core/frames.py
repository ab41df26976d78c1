"""Which frames are solved, how the frames between them are interpolated, and attribute names.

With a frame step ``k`` the frames ``start, start+k, ...`` are solved, and ``end`` always is; a
frame in between gets the linear interpolation of the corner colours of its two solved
neighbours. Attribute names are ``Rad_`` + the frame zero-padded to 4 digits, which the Geometry
Nodes switch rebuilds as ``"Rad_" + slice(str(frame + 10000), 1, 4)``: frames must lie in 0..9999.
A bake writes its frames under staging names (``RadNew_0001``...), which the switch never reads,
and renames them to ``Rad_`` names only when it ends with something to keep (``bake.py``).
"""

from __future__ import annotations

ATTRIBUTE_PREFIX = "Rad_"
STAGING_PREFIX = "RadNew_"
RESULT_ATTRIBUTE = "Radiosity"
# The irradiance H / pi (light only, without the surface's colour and emission), per frame and
# switched likewise into LIGHT_ATTRIBUTE, which "Apply to Materials" multiplies with a material's
# own colour (``blender/light_nodes.py``).
LIGHT_PREFIX = "Irr_"
LIGHT_STAGING_PREFIX = "IrrNew_"
LIGHT_ATTRIBUTE = "Radiosity Light"
MIN_FRAME = 0
MAX_FRAME = 9999


def check_frame(frame: int) -> None:
    if not MIN_FRAME <= frame <= MAX_FRAME:
        from .settings import SettingsError

        raise SettingsError(
            f"frame {frame} is outside {MIN_FRAME}..{MAX_FRAME} "
            "(the colour attributes are named Rad_0000..Rad_9999)"
        )


def attribute_name(frame: int, prefix: str = ATTRIBUTE_PREFIX) -> str:
    check_frame(frame)
    return f"{prefix}{frame:04d}"


def staging_name(frame: int, prefix: str = STAGING_PREFIX) -> str:
    check_frame(frame)
    return f"{prefix}{frame:04d}"


def frame_of_attribute(name: str, prefix: str = ATTRIBUTE_PREFIX) -> int | None:
    """The frame of a ``Rad_NNNN`` name (``RadNew_NNNN`` with ``prefix=STAGING_PREFIX``), None
    for any other name."""
    if len(name) == len(prefix) + 4 and name.startswith(prefix):
        digits = name[len(prefix):]
        if digits.isdigit():
            return int(digits)
    return None


def baked_frames(start: int, end: int, step: int) -> list[int]:
    """Frames that are solved: every ``step``-th from ``start``, and ``end``."""
    if step < 1 or start > end:
        raise ValueError(f"bad frame range {start}-{end} step {step}")
    out = list(range(start, end + 1, step))
    if out[-1] != end:
        out.append(end)
    return out


def between(f0: int, f1: int) -> list[tuple[int, float]]:
    """Frames strictly between two solved frames with the weight of ``f1``: (frame, w)."""
    return [(f, (f - f0) / (f1 - f0)) for f in range(f0 + 1, f1)]
