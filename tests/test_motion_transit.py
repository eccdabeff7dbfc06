"""Moves between cuts (motion.transit): the straight line when clear, around obstacles else."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from scrapcut_cli.motion.transit import TransitSettings, plan_transit, segment_samples

LOWER = np.full(7, -2.0)
UPPER = np.full(7, 2.0)


def _wall(q: np.ndarray) -> np.ndarray:
    """A wall in joint space across joint 0 at 0, open only where joint 1 > 0.8."""
    q = np.atleast_2d(q)
    return (np.abs(q[:, 0]) < 0.15) & (q[:, 1] < 0.8)


def _dense_clear(path: np.ndarray, collides: object, step: float = 0.005) -> bool:
    return not any(
        collides(segment_samples(a, b, step)).any()  # type: ignore[operator]
        for a, b in itertools.pairwise(path)
    )


def test_a_clear_line_stays_a_line_and_a_wall_is_gone_around() -> None:
    a, b = np.zeros(7), np.zeros(7)
    a[0], b[0] = -0.6, 0.6
    clear = plan_transit(a, b, lambda q: np.zeros(len(np.atleast_2d(q)), bool), LOWER, UPPER,
                         np.random.default_rng(0))  # fmt: skip
    assert clear is not None and clear.shape == (2, 7)
    path = plan_transit(a, b, _wall, LOWER, UPPER, np.random.default_rng(0))
    assert path is not None and len(path) >= 3
    assert np.array_equal(path[0], a) and np.array_equal(path[-1], b)
    assert _dense_clear(path, _wall)
    assert np.max(path[:, 1]) > 0.8  # over the wall's opening
    assert np.all(path >= LOWER) and np.all(path <= UPPER)
    again = plan_transit(a, b, _wall, LOWER, UPPER, np.random.default_rng(0))
    assert again is not None and np.array_equal(path, again)  # seeded: the same path


@pytest.mark.parametrize("blocked", ["goal", "closed"])
def test_no_path_is_none(blocked: str) -> None:
    a, b = np.zeros(7), np.zeros(7)
    a[0], b[0] = -0.6, 0.6

    def collides(q: np.ndarray) -> np.ndarray:
        q = np.atleast_2d(q)
        if blocked == "goal":
            return np.linalg.norm(q - b, axis=1) < 0.1
        return np.abs(q[:, 0]) < 0.15  # a wall across every joint-1 value

    settings = TransitSettings(max_samples=200)
    assert plan_transit(a, b, collides, LOWER, UPPER, np.random.default_rng(0), settings) is None
