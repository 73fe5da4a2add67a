"""Writes scenes/smoke.vol, the density grid of scenes/smoke.xml (issue 44): a plume of smoke.

The plume rises from a dense core near the bottom of the grid, widening and thinning as it
climbs along a slowly wavering axis; a few fixed random sinusoids break it into puffs. Cells
below a small threshold are set to exactly zero, so most of the grid is empty: a single global
majorant (the peak density) then proposes mostly null collisions, which a majorant grid avoids.

Plain numpy, deterministic (fixed seed; values rounded to multiples of 1/4096 so a last-bit
difference in a libm cannot change the file), no Mitsuba needed. Run from anywhere:

    python scenes/make_smoke.py            # rewrites scenes/smoke.vol

The file is Mitsuba's binary grid format (what ``gridvolume`` reads, as ``mi.VolumeGrid.write``
writes it): the bytes ``VOL``, version 3, int32 encoding 1 (float32), int32 sizes x, y, z, int32
channel count, six float32 bounds (min xyz, max xyz; gridvolume ignores them and maps the grid to
the unit cube, placed by its ``to_world``), then float32 values with x varying fastest, then y, z.
"""
from __future__ import annotations

import os
import struct
import sys

import numpy as np

SEED = 44
SHAPE = (32, 48, 32)            # cells along x, y (up), z: 196 KB of float32
THRESHOLD = 0.02                # densities below this become empty cells
QUANTUM = 1.0 / 4096
HERE = os.path.dirname(os.path.abspath(__file__))
OUT = os.path.join(HERE, "smoke.vol")


def smoke_density(seed: int = SEED, shape=SHAPE) -> np.ndarray:
    """The plume's density in [0, 1], indexed ``[z, y, x]`` (the file's order, x fastest)."""
    nx, ny, nz = shape
    rng = np.random.default_rng(seed)
    # Cell centres in [0, 1]^3.
    z, y, x = np.meshgrid((np.arange(nz) + 0.5) / nz, (np.arange(ny) + 0.5) / ny,
                          (np.arange(nx) + 0.5) / nx, indexing="ij")
    # The axis wavers as it rises; the plume widens with height.
    ax = 0.5 + 0.10 * np.sin(2 * np.pi * (1.2 * y + 0.1))
    az = 0.5 + 0.07 * np.sin(2 * np.pi * (0.8 * y + 0.35))
    radius = 0.07 + 0.20 * y
    d2 = ((x - ax) ** 2 + (z - az) ** 2) / radius**2
    # Dense at the bottom, thinning upwards (mass spreads over a wider section); nothing below
    # the source (y < 0.06) and a soft top so the plume ends inside the grid.
    height = np.clip((y - 0.04) / 0.06, 0, 1) * np.clip((0.95 - y) / 0.25, 0, 1)
    core = np.exp(-2.5 * d2) * (0.07 / radius) ** 1.2 * height
    # Puffs: a product of four random low-frequency waves, each between 0.75 and 1.25.
    puffs = np.ones_like(core)
    for _ in range(4):
        k = rng.normal(0.0, 6.0, 3)
        phase = rng.uniform(0, 2 * np.pi)
        puffs *= 1.0 + 0.25 * np.sin(k[0] * x + k[1] * y * 1.5 + k[2] * z + phase)
    density = core * puffs
    density /= density.max()
    density[density < THRESHOLD] = 0.0
    return (np.round(density / QUANTUM) * QUANTUM).astype(np.float32)


def vol_bytes(density: np.ndarray, bbox=((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))) -> bytes:
    """One-channel float32 grid ``[z, y, x]`` in Mitsuba's .vol format (module doc)."""
    nz, ny, nx = density.shape
    header = b"VOL" + struct.pack("<B", 3) + struct.pack("<iiiii", 1, nx, ny, nz, 1)
    header += struct.pack("<6f", *bbox[0], *bbox[1])
    return header + np.ascontiguousarray(density, dtype="<f4").tobytes()


def main(out: str = OUT) -> str:
    data = vol_bytes(smoke_density())
    with open(out, "wb") as f:
        f.write(data)
    return out


if __name__ == "__main__":
    print(main(*sys.argv[1:]))
