"""Depth as real cameras give it: noise, quantisation, holes at edges, flying pixels, speckle.

Applied to a rendered depth picture (metres, NaN = no reading) after rendering, reproducibly
from a seed. Every step is whole-array NumPy; the normal deviates come from a pool drawn once
per camera, read from a random offset each capture, because drawing 300,000 fresh normals costs
more than the 20 % of a 640 x 480 capture the noise may take (see benchmarks/bench_sim.py).

The steps, each off at its zero value, in the order they are applied:

- ``edge_px``: no reading within ``edge_px`` pixels of a depth edge (a jump between
  neighbours of more than 1 cm + 1 % of the depth), except a ``flying_share`` of those pixels,
  which read a "flying pixel" somewhere between the near and the far surface of the edge;
- ``sigma_m`` and the axial ``a``, ``b``, ``c``: a normal error along the ray with
  sigma(z) = sigma_m + a + b·(z - c)², the form published for structured-light cameras
  (Nguyen, Izadi, Lovell, "Modeling Kinect sensor noise for improved 3D reconstruction and
  tracking", 3DIMPVT 2012: sigma(z) = 0.0012 + 0.0019·(z - 0.4)² m);
- ``step_m``: readings rounded to whole steps (16UC1 pictures are whole millimetres);
- ``speckle_share``: that share of the picture replaced by wrong, much nearer readings
  (30-80 % of the true distance), alone or in square clumps up to ``clump_px`` across, as
  structured-light cameras give on dark or shiny spots.

``colour_sigma`` adds a camera sensor's noise to the colour picture
(:meth:`DepthNoise.colour`): a normal error of that sigma (levels of 0..255) on each channel of
each pixel, rounded and clipped. Real colour in a lit room errs by a few levels; in dim light,
at a high gain, by ten or more. The presets leave the colour clean.

``correlation_px`` makes the normal error lumpy: the pool is smoothed once by a Gaussian of
that sigma, in pixels, and scaled back to unit variance, so neighbours err together as behind
a stereo camera's matching window or a depth filter, at the same sigma.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
import numpy.typing as npt
from scipy import ndimage

from onebox.errors import SceneError

Float32Array = npt.NDArray[np.float32]


@dataclass(frozen=True)
class NoiseSpec:
    """One noise model's numbers; every step is off at its zero value."""

    model: str = "none"
    sigma_m: float = 0.0
    a: float = 0.0
    b: float = 0.0
    c: float = 0.0
    step_m: float = 0.0
    edge_px: int = 0
    flying_share: float = 0.0
    speckle_share: float = 0.0
    clump_px: int = 1
    correlation_px: float = 0.0
    colour_sigma: float = 0.0
    seed: int = 0

    @property
    def is_off(self) -> bool:
        return not (
            self.sigma_m or self.a or self.b or self.step_m or self.edge_px or self.speckle_share
        )

    def sigma_at(self, z_m: npt.ArrayLike) -> npt.NDArray[np.float64]:
        """sigma of the normal error at depth ``z_m``, metres (before quantisation)."""
        z = np.asarray(z_m, dtype=np.float64)
        return self.sigma_m + self.a + self.b * (z - self.c) ** 2

    def expected_sigma(self, z_m: float) -> float:
        """sigma of the whole error on a flat surface at ``z_m`` without edges or speckle: the
        normal error and the rounding's uniform error (step / √12) added in quadrature."""
        return float(np.sqrt(self.sigma_at(z_m) ** 2 + self.step_m**2 / 12))


# The Intel RealSense D435, a stereo camera, at 848 x 480 (its best depth mode):
# - "Intel RealSense Camera Depth Testing Methodology" and the white paper "Tuning depth cameras
#   for best performance" (Grunnet-Jepsen et al., Intel) give the RMS depth error as
#   z² · subpixel / (focal_px · baseline): subpixel 0.08, baseline 50 mm, focal_px 0.5 · 848 /
#   tan(87° / 2) = 447 px, so b = 0.08 / (447 · 0.050) = 0.0036 per metre, a = c = 0:
#   sigma(1 m) = 3.6 mm, sigma(2 m) = 14 mm (the D400 datasheet promises RMS error ≤ 2 % at 2 m).
# - The depth unit is 1 mm (the SDK's default depth scale 0.001), so steps of 1 mm.
# - The datasheet's fill rate ≥ 99 % leaves holes for stereo's occlusion bands at edges (we take
#   2 px) and its left-right check keeps few flying pixels (we take 10 % of that band); speckle
#   on dark or shiny spots, 0.1 % of the picture in clumps up to 3 px.
D435 = NoiseSpec(
    model="d435",
    b=0.0036,
    step_m=0.001,
    edge_px=2,
    flying_share=0.1,
    speckle_share=0.001,
    clump_px=3,
)

# The Microsoft Azure Kinect DK, a time-of-flight camera (learn.microsoft.com/azure/kinect-dk/
# hardware-specification and .../depth-camera): "random error std. dev. ≤ 17 mm" and
# "systematic error < 11 mm + 0.1 % of distance". Time-of-flight noise grows with distance (the
# returned light falls with z²); we take sigma = b·z² reaching the 17 mm bound at the far end of the
# NFOV unbinned range, 3.86 m: b = 0.017 / 3.86² = 0.00114 per metre (sigma(1 m) = 1.1 mm,
# sigma(2 m) = 4.6 mm). The systematic error is a per-device bias, not noise, and is left out.
# Depth comes in whole millimetres; flying pixels at edges are time of flight's known artefact
# (mixed returns), so a larger share of the 1 px band flies; no structured-light speckle.
AZURE_KINECT = NoiseSpec(
    model="azure_kinect",
    b=0.00114,
    step_m=0.001,
    edge_px=1,
    flying_share=0.5,
)

PRESETS: dict[str, NoiseSpec] = {
    "none": NoiseSpec(),
    "gaussian": NoiseSpec(model="gaussian", sigma_m=0.002),
    "axial": NoiseSpec(model="axial", a=0.0012, b=0.0019, c=0.4),
    "quantise": NoiseSpec(model="quantise", step_m=0.001),
    "edge_dropout": NoiseSpec(model="edge_dropout", edge_px=2, flying_share=0.2),
    "speckle": NoiseSpec(model="speckle", speckle_share=0.002, clump_px=3),
    "d435": D435,
    "azure_kinect": AZURE_KINECT,
}
"""Every model by name, with its default numbers; a scene's [noise] numbers override them."""

KEYS = tuple(f.name for f in dataclasses.fields(NoiseSpec))


def noise_spec(table: dict[str, Any], where: str = "noise") -> NoiseSpec:
    """The [noise] table of a scene: ``model`` picks the defaults, the other keys override."""
    unknown = sorted(set(table) - set(KEYS))
    if unknown:
        raise SceneError(f"unknown key {where}.{unknown[0]} (known: {', '.join(KEYS)})")
    model = table.get("model", "none")
    if model not in PRESETS:
        raise SceneError(
            f"{where}.model = {model!r}: unknown noise model; use one of {', '.join(PRESETS)}"
        )
    values: dict[str, Any] = {}
    for f in dataclasses.fields(NoiseSpec):
        if f.name == "model" or f.name not in table:
            continue
        value = table[f.name]
        integral = f.name in {"edge_px", "clump_px", "seed"}
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise SceneError(f"{where}.{f.name} = {value!r}: expected a number")
        if integral and not isinstance(value, int):
            raise SceneError(f"{where}.{f.name} = {value!r}: expected a whole number")
        if f.name != "c" and f.name != "seed" and value < 0:
            raise SceneError(f"{where}.{f.name} = {value!r}: must not be negative")
        if f.name in {"flying_share", "speckle_share"} and value > 1:
            raise SceneError(f"{where}.{f.name} = {value!r}: a share, from 0 to 1")
        values[f.name] = value if integral else float(value)
    if values.get("clump_px", 1) < 1:
        raise SceneError(f"{where}.clump_px = {values['clump_px']}: at least 1")
    return dataclasses.replace(PRESETS[model], **values)


def noise_table(spec: NoiseSpec) -> dict[str, Any]:
    """The [noise] table that gives ``spec``: the model and the numbers that differ from it."""
    preset = PRESETS[spec.model]
    table: dict[str, Any] = {"model": spec.model}
    for f in dataclasses.fields(NoiseSpec):
        value = getattr(spec, f.name)
        if f.name != "model" and value != getattr(preset, f.name):
            table[f.name] = value
    return table


class DepthNoise:
    """Applies one NoiseSpec to every capture of one camera, reproducibly from its seed."""

    def __init__(self, spec: NoiseSpec, shape: tuple[int, int], stream: int = 0) -> None:
        self.spec = spec
        self._shape = shape
        self._rng = np.random.default_rng([spec.seed, stream])
        size = shape[0] * shape[1]
        self._normals: Float32Array | None = None
        self._colour_normals: npt.NDArray[np.int16] | None = None
        if spec.sigma_m or spec.a or spec.b:
            # A pool four pictures long, read from a random offset each capture (with a random
            # sign): one capture's errors are independent normals, at a tenth of the cost.
            self._normals = self._rng.standard_normal(4 * size, dtype=np.float32)
            if spec.correlation_px > 0:
                # Lumpy: smoothed as four pictures stacked (the edges wrap, so no border is
                # smoother than the rest), read from a whole row's offset so that no seam runs
                # down the picture.
                pool = self._normals.reshape(4 * shape[0], shape[1])
                pool = ndimage.gaussian_filter(pool, spec.correlation_px, mode="wrap")
                pool /= pool.std()
                self._normals = pool.reshape(-1)

    def colour(self, rgb: npt.NDArray[np.uint8]) -> npt.NDArray[np.uint8]:
        """A noisy copy of ``rgb`` (H x W x 3) with ``colour_sigma``; the input is not changed."""
        sigma = self.spec.colour_sigma
        if not sigma:
            return rgb
        if self._colour_normals is None or self._colour_normals.size < 2 * rgb.size:
            # Like the depth's: a pool two pictures long, in whole levels, read from a random
            # offset each capture.
            pool = self._rng.standard_normal(2 * rgb.size, dtype=np.float32) * np.float32(sigma)
            self._colour_normals = np.rint(pool).astype(np.int16)
        offset = int(self._rng.integers(0, self._colour_normals.size - rgb.size + 1))
        noisy = rgb.astype(np.int16)
        noisy += self._colour_normals[offset : offset + rgb.size].reshape(rgb.shape)
        np.clip(noisy, 0, 255, out=noisy)
        return noisy.astype(np.uint8)

    def apply(self, depth_m: Float32Array) -> Float32Array:
        """A noisy copy of ``depth_m`` (metres, NaN = no reading); the input is not changed."""
        spec = self.spec
        if spec.is_off:
            return depth_m
        out = depth_m.copy()
        if spec.edge_px:
            self._edges(depth_m, out)
        if self._normals is not None:
            sigma = np.subtract(depth_m, np.float32(spec.c), dtype=np.float32)
            np.square(sigma, out=sigma)
            sigma *= np.float32(spec.b)
            sigma += np.float32(spec.sigma_m + spec.a)
            size = out.size
            offset = int(self._rng.integers(0, self._normals.size - size + 1))
            if spec.correlation_px > 0:
                offset -= offset % out.shape[1]
            if self._rng.integers(2):
                sigma *= np.float32(-1)
            sigma *= self._normals[offset : offset + size].reshape(out.shape)
            out += sigma
        if spec.step_m:
            step = np.float32(spec.step_m)
            np.divide(out, step, out=out)
            np.rint(out, out=out)
            out *= step
        if spec.speckle_share:
            self._speckle(depth_m, out)
        return out

    def _edges(self, clean: Float32Array, out: Float32Array) -> None:
        """Holes within edge_px of a depth jump; a share of them become flying pixels."""
        spec = self.spec
        height, width = clean.shape
        with np.errstate(invalid="ignore"):
            limit = clean * np.float32(0.01)
            limit += np.float32(0.01)
            jump = np.diff(clean, axis=1)
            np.abs(jump, out=jump)
            edge_x = jump > limit[:, 1:]
            jump = np.diff(clean, axis=0)
            np.abs(jump, out=jump)
            edge_y = jump > limit[1:]
        # A jump between two pixels marks both; the band then grows edge_px - 1 more each way,
        # along the rows and then along the columns.
        band = np.zeros((height, width), bool)
        band[:, 1:] = edge_x
        band[:, :-1] |= edge_x
        band[1:] |= edge_y
        band[:-1] |= edge_y
        if spec.edge_px > 1:
            grown = band.copy()
            for k in range(1, spec.edge_px):
                grown[:, k:] |= band[:, :-k]
                grown[:, :-k] |= band[:, k:]
            band = grown.copy()
            for k in range(1, spec.edge_px):
                band[k:] |= grown[:-k]
                band[:-k] |= grown[k:]
        if not spec.flying_share:
            out[band] = np.nan
            return
        rows, cols = np.nonzero(band)
        flying = self._rng.random(rows.size) < spec.flying_share
        out[rows[~flying], cols[~flying]] = np.nan
        if not flying.any():
            return
        # A flying pixel lies on the ray between the nearest and farthest surface around it.
        r, c = rows[flying], cols[flying]
        reach = spec.edge_px + 1
        offsets = np.arange(-reach, reach + 1)
        rr = np.clip(r[:, None] + offsets[None, :], 0, height - 1)
        cc = np.clip(c[:, None] + offsets[None, :], 0, width - 1)
        around = np.concatenate([clean[rr, c[:, None]], clean[r[:, None], cc]], axis=1)
        near, far = np.nanmin(around, axis=1), np.nanmax(around, axis=1)
        mix = self._rng.random(r.size, dtype=np.float32)
        out[r, c] = near + mix * (far - near)

    def _speckle(self, clean: Float32Array, out: Float32Array) -> None:
        """speckle_share of the pixels replaced by a much nearer reading, in small clumps."""
        spec = self.spec
        height, width = clean.shape
        k = spec.clump_px
        mean_clump = (k + 1) * (2 * k + 1) / 6  # the mean of side² for sides 1..k, equally likely
        count = round(spec.speckle_share * clean.size / mean_clump)
        if count == 0:
            return
        rows = self._rng.integers(0, height, count)
        cols = self._rng.integers(0, width, count)
        sides = self._rng.integers(1, spec.clump_px + 1, count)
        factor = self._rng.uniform(0.3, 0.8, count).astype(np.float32)
        for dy in range(spec.clump_px):
            for dx in range(spec.clump_px):
                inside = (dy < sides) & (dx < sides)
                r = np.minimum(rows[inside] + dy, height - 1)
                c = np.minimum(cols[inside] + dx, width - 1)
                out[r, c] = clean[r, c] * factor[inside]
