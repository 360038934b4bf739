"""Depth noise on known surfaces: each model's measured spread against its formula."""

from __future__ import annotations

import dataclasses

import numpy as np
import numpy.typing as npt
import pytest

from onebox.world.noise import PRESETS, DepthNoise, NoiseSpec

SHAPE = (480, 640)


def ramp(near_m: float, far_m: float) -> npt.NDArray[np.float32]:
    """A flat surface seen at a slant: depth rising evenly from the top row to the bottom."""
    column = np.linspace(near_m, far_m, SHAPE[0], dtype=np.float32)
    return np.repeat(column[:, None], SHAPE[1], axis=1)


def errors(spec: NoiseSpec, clean: npt.NDArray[np.float32], frames: int = 3) -> np.ndarray:
    noise = DepthNoise(spec, SHAPE)
    return np.stack([noise.apply(clean) - clean for _ in range(frames)])


@pytest.mark.parametrize(
    ("spec", "near_m", "far_m"),
    [
        (NoiseSpec(model="gaussian", sigma_m=0.004), 1.0, 1.0),
        (PRESETS["gaussian"], 0.5, 0.6),
        (PRESETS["axial"], 2.0, 2.0),
        (PRESETS["axial"], 0.5, 0.5),
        (PRESETS["quantise"], 1.0, 1.1),
        (NoiseSpec(model="quantise", step_m=0.005), 1.0, 1.5),
        (PRESETS["d435"], 1.0, 1.0),
        (PRESETS["d435"], 2.0, 2.0),
        (PRESETS["azure_kinect"], 2.5, 2.5),
    ],
)
def test_measured_sigma_on_a_flat_surface_follows_the_formula(
    spec: NoiseSpec, near_m: float, far_m: float
) -> None:
    """sigma(z) = sigma_m + a + b (z - c)^2, with step / sqrt(12) of rounding, within 10 %."""
    clean = ramp(near_m, far_m)
    err = errors(spec, clean).astype(np.float64)
    z = np.broadcast_to(clean, err.shape)
    expected = np.array([spec.expected_sigma(d) for d in np.unique(clean)])
    kept = np.abs(err) < 0.1 * z  # speckle is far off the surface, counted on its own below
    assert kept.mean() > 0.99
    measured = np.sqrt(np.mean(err[kept] ** 2))
    want = float(np.sqrt(np.mean(expected**2)))
    assert measured == pytest.approx(want, rel=0.10), (measured, want)


def test_lumpy_noise_keeps_its_sigma_and_neighbours_err_together() -> None:
    """correlation_px smooths the normal error: the same sigma on a flat surface, neighbours'
    errors correlated as a Gaussian of that width leaves them (exp(-d^2 / 4 s^2): 0.99 one
    pixel apart at 5 px, 0.37 ten apart), none across a seam in the picture, and each capture
    its own lumps."""
    spec = dataclasses.replace(PRESETS["gaussian"], sigma_m=0.003, correlation_px=5.0)
    clean = ramp(1.0, 1.0)
    err = errors(spec, clean).astype(np.float64)
    assert np.sqrt(np.mean(err**2)) == pytest.approx(0.003, rel=0.10)
    for frame in err:
        for axis in (0, 1):
            for apart, want in ((1, 0.99), (10, 0.37)):
                a = np.take(frame, range(0, frame.shape[axis] - apart), axis=axis)
                b = np.take(frame, range(apart, frame.shape[axis]), axis=axis)
                assert np.corrcoef(a.ravel(), b.ravel())[0, 1] == pytest.approx(want, abs=0.1)
        # No column where the lumps break off: every column's step to the next is small.
        steps = np.sqrt(np.mean(np.diff(frame, axis=1) ** 2, axis=0))
        assert steps.max() < 0.2 * 0.003
    assert abs(np.corrcoef(err[0].ravel(), err[1].ravel())[0, 1]) < 0.3


def test_none_leaves_the_picture_alone() -> None:
    """Model none returns the rendered depth untouched."""
    clean = ramp(0.5, 1.0)
    assert DepthNoise(PRESETS["none"], SHAPE).apply(clean) is clean


@pytest.mark.parametrize("name", ["speckle", "d435"])
def test_speckle_share_and_clumps(name: str) -> None:
    """The speckle share of the readings are much nearer (30-80 %), in clumps up to clump_px."""
    spec = PRESETS[name]
    clean = ramp(1.0, 1.0)
    err = errors(spec, clean, frames=8)
    speckled = err < -0.1
    assert speckled.mean() == pytest.approx(spec.speckle_share, rel=0.10)
    ratio = 1 + err[speckled]  # the true depth is 1 m
    assert ratio.min() >= 0.3 - 1e-6 and ratio.max() <= 0.8 + 1e-6
    # clumps: many speckled pixels have a speckled neighbour
    frame = speckled[0]
    neighbour = frame[:, 1:] & frame[:, :-1]
    assert neighbour.sum() > 0.2 * frame.sum()


def test_edges_lose_their_readings_and_fly() -> None:
    """Within edge_px of a depth step no reading, but flying_share of the band lies between."""
    spec = dataclasses.replace(PRESETS["edge_dropout"], edge_px=2, flying_share=0.2)
    clean = np.full(SHAPE, 1.0, np.float32)
    clean[:, 320:] = 1.5
    out = np.stack([DepthNoise(spec, SHAPE, stream=i).apply(clean) for i in range(3)])
    band = out[:, :, 318:322]
    assert np.array_equal(out[:, :, :318], np.broadcast_to(clean[:, :318], out[:, :, :318].shape))
    assert np.array_equal(out[:, :, 322:], np.broadcast_to(clean[:, 322:], out[:, :, 322:].shape))
    flying = np.isfinite(band)
    assert flying.mean() == pytest.approx(0.2, rel=0.10)
    assert np.all((band[flying] >= 1.0) & (band[flying] <= 1.5))


def test_the_same_seed_gives_the_same_noise() -> None:
    """Two cameras with one seed give identical noisy pictures; another seed does not."""
    clean = ramp(0.8, 2.0)
    spec = PRESETS["d435"]
    a = [DepthNoise(spec, SHAPE).apply(clean)]
    first, second = DepthNoise(spec, SHAPE), DepthNoise(spec, SHAPE)
    for _ in range(3):
        assert first.apply(clean).tobytes() == second.apply(clean).tobytes()
    other = DepthNoise(dataclasses.replace(spec, seed=1), SHAPE).apply(clean)
    assert other.tobytes() != a[0].tobytes()


def test_colour_noise_has_its_sigma_and_leaves_the_depth_alone() -> None:
    """colour_sigma errs every channel of every pixel by a normal error of that sigma (whole
    levels, clipped to 0..255), differently each capture; without it the colour is untouched,
    and it changes nothing of the depth's noise but its draws."""
    grey = np.full((*SHAPE, 3), 128, np.uint8)
    clean = ramp(1.0, 1.0)
    assert DepthNoise(PRESETS["d435"], SHAPE).colour(grey) is grey
    spec = dataclasses.replace(PRESETS["none"], colour_sigma=6.0)
    noise = DepthNoise(spec, SHAPE)
    assert noise.apply(clean) is clean
    first, second = noise.colour(grey), noise.colour(grey)
    assert first.dtype == np.uint8 and first.shape == grey.shape
    assert np.array_equal(grey, np.full_like(grey, 128))  # the input is not changed
    err = first.astype(np.float64) - 128
    assert np.sqrt(np.mean(err**2)) == pytest.approx(6.0, rel=0.10)
    assert abs(err.mean()) < 0.1
    assert not np.array_equal(first, second)
    bright = noise.colour(np.full((*SHAPE, 3), 252, np.uint8))
    assert bright.max() == 255 and (bright == 255).mean() > 0.2
