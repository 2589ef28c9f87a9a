"""Accuracy of every preset on tabulated BRDFs, as tests/test_accuracy.py measures it for Cook-Torrance:
under each of Blender's eight bundled HDRIs, over the same 2000 random (normal, view) pairs, against
wenv.reference of the same table.  The tables are 90 x 90 x 180 (MERL's resolution) of numpy BRDFs
(tests/helpers/merl_files.py, table_of): the Cook-Torrance lobes of test_accuracy.py (m = 0.05..0.5,
white, index 1.5), a paint (m = 0.2 over a coloured diffuse floor, which the table splits off as a
Lambertian part), a retro-reflective lobe and a lobe whose colour shifts with theta_d.

The reference values are stored in data/accuracy_reference_tables.npz by
benchmarks/accuracy.py --make-table-reference (about 25 min); test_stored_reference_is_current
recomputes a sample of them."""
import json
import os
import sys

import numpy as np
import pytest

import wenv

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
from tests.helpers import merl_files as M  # noqa: E402
import test_accuracy  # noqa: E402  (the Cook-Torrance figures, computed once per session)

DATA = os.path.join(os.path.dirname(__file__), "data", "accuracy_reference_tables.npz")

# Worst relative RMSE over the eight HDRIs per preset and table: the measured worst case
# (benchmarks/accuracy.py --tables prints the full table) with 10 % headroom.  With the samples at
# the bins' centres (the tables' last theta_d sample at 89.5 degrees, where the lobes rise steeply,
# instead of 89) views past 84 degrees err more on t0.05, t0.1 and t0.5 (high: 0.57 -> 0.78 % at
# t0.1, 1.11 -> 1.33 % at t0.5); every other band of views is unchanged.
BOUNDS = {
    "draft": {"t0.05": 0.897, "t0.1": 0.822, "t0.2": 0.68, "t0.5": 0.285, "paint": 0.59, "retro": 0.179, "tinted": 0.493},
    "default": {"t0.05": 0.0528, "t0.1": 0.0300, "t0.2": 0.0180, "t0.5": 0.0301, "paint": 0.0108, "retro": 0.0124,
                "tinted": 0.0189},
    "high": {"t0.05": 0.0146, "t0.1": 0.00861, "t0.2": 0.0112, "t0.5": 0.0147, "paint": 0.00652, "retro": 0.0086,
             "tinted": 0.0102},
}
METHOD = test_accuracy.METHOD


@pytest.fixture(scope="module")
def data():
    return np.load(DATA)


@pytest.fixture(scope="module")
def tables(data):
    return {name: wenv.Tabulated(M.table_of(spec)) for name, spec in json.loads(str(data["materials"])).items()}


_errors = {}


def preset_errors(preset, data, tables):
    """{(hdri, table): relative RMSE} for one preset, computed once per test session."""
    if preset not in _errors:
        _errors[preset] = test_accuracy.shade_errors(preset, data, tables)
    return _errors[preset]


def test_stored_reference_is_current(data, tables):
    test_accuracy.assert_stored_reference_current(data, tables, [("sunset", "paint"), ("forest", "retro"),
                                                                 ("studio", "t0.05")], np.arange(3, 2000, 125))


def test_same_pairs_as_cook_torrance(data):
    ct = np.load(test_accuracy.DATA)
    np.testing.assert_array_equal(data["normals"], ct["normals"])
    np.testing.assert_array_equal(data["views"], ct["views"])


@pytest.mark.parametrize("preset", ["draft", "default", "high"])
def test_relative_rmse_within_preset_bounds(preset, data, tables):
    test_accuracy.assert_within_bounds(preset, preset_errors(preset, data, tables), BOUNDS, data, len(tables))


@pytest.mark.parametrize("preset", ["draft", "default", "high"])
def test_a_table_shades_as_accurately_as_its_lobe(preset, data, tables):
    """The BRDF enters the methods only through its slices, lights and rules: the table of a
    Cook-Torrance lobe errs as that lobe does at the same preset (median over the HDRIs within
    1.35x + 0.1 point, worst within 1.5x + 0.2 points).  (The median was within 1.25x while the
    samples sat at the bins' starts; t0.5's is now 1.34x its lobe's at default, 1.66 against
    1.24 %, and 1.53x at high, 0.65 against 0.42 %, from views past 84 degrees: see BOUNDS.)"""
    mine = preset_errors(preset, data, tables)
    ct = test_accuracy.preset_errors(preset, np.load(test_accuracy.DATA))
    for m in ("0.05", "0.1", "0.2", "0.5"):
        a = [mine[(h, f"t{m}")] for h in json.loads(str(data["hdris"]))]
        b = [ct[(h, f"m{m}")] for h in json.loads(str(data["hdris"]))]
        assert np.median(a) <= 1.35 * np.median(b) + 0.001, (preset, m, np.median(a), np.median(b))
        assert max(a) <= 1.5 * max(b) + 0.002, (preset, m, max(a), max(b))


def test_higher_presets_are_more_accurate(data, tables):
    draft, default, high = (preset_errors(p, data, tables) for p in ("draft", "default", "high"))
    for name in tables:
        median = [np.median([e[k] for k in e if k[1] == name]) for e in (draft, default, high)]
        assert median[0] > median[1] > median[2], (name, median)
