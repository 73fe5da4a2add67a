"""Writes scenes/fog.vol, the density grid of scenes/fog_lantern.xml (issue 44): thin uneven fog.

Ground fog that thins with height (0.5 at the floor to 0.1 at the top) with gentle waves across it
(+-30%, two fixed sinusoids); no cell is empty, unlike smoke.vol, so the fog fills its whole box:
equi-angular sampling's case, light scattered everywhere along a ray near a point light.
Deterministic, plain numpy, the same file format as make_smoke.py (whose writer it uses):

    python scenes/make_fog.py              # rewrites scenes/fog.vol
"""
from __future__ import annotations

import os
import sys

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)        # make_smoke beside it, however this file was loaded
from make_smoke import QUANTUM, vol_bytes  # noqa: E402

SHAPE = (16, 16, 16)            # cells along x, y (up), z
OUT = os.path.join(HERE, "fog.vol")


def fog_density(shape=SHAPE) -> np.ndarray:
    """The fog's density, indexed ``[z, y, x]`` (the file's order, x fastest)."""
    nx, ny, nz = shape
    z, y, x = np.meshgrid(*(np.linspace(0, 1, n) for n in (nz, ny, nx)), indexing="ij")
    layers = 0.1 + 0.4 * np.exp(-3.0 * y)
    waves = 1.0 + 0.3 * np.sin(2 * np.pi * (1.3 * x + 0.4 * y)) * np.cos(2 * np.pi * (0.9 * z - 0.5 * x))
    return np.round(layers * waves / QUANTUM) * QUANTUM


def main(out: str = OUT) -> str:
    with open(out, "wb") as f:
        f.write(vol_bytes(fog_density()))
    return out


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
