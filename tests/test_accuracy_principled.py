"""Accuracy of every preset on Blender's Principled BSDF, as tests/test_accuracy.py measures it for
Cook-Torrance: under each of the eight bundled HDRIs, over the same 2000 random (normal, view) pairs,
against wenv.reference of the same material -- a paint, a metal, a coated paint and a satin plastic
(benchmarks/accuracy.py's PRINCIPLED).

The reference values are stored in data/accuracy_reference_principled.npz by
benchmarks/accuracy.py --make-principled-reference; test_stored_reference_is_current recomputes a
sample of them."""
import json
import os

import numpy as np
import pytest

import wenv
import test_accuracy

DATA = os.path.join(os.path.dirname(__file__), "data", "accuracy_reference_principled.npz")

# Worst relative RMSE over the eight HDRIs per preset and material: the measured worst case
# (benchmarks/accuracy.py --principled prints the full table) with 10 % headroom.
BOUNDS = {
    "draft": {"paint": 0.759, "metal": 0.706, "coated": 1.03, "satin": 0.12},
    "default": {"paint": 0.0227, "metal": 0.0298, "coated": 0.0969, "satin": 0.0063},
    "high": {"paint": 0.00484, "metal": 0.0119, "coated": 0.081, "satin": 0.00281},
}


@pytest.fixture(scope="module")
def data():
    return np.load(DATA)


@pytest.fixture(scope="module")
def materials(data):
    return {name: wenv.Principled(**spec["principled"]) for name, spec in json.loads(str(data["materials"])).items()}


_errors = {}


def preset_errors(preset, data, materials):
    if preset not in _errors:
        _errors[preset] = test_accuracy.shade_errors(preset, data, materials)
    return _errors[preset]


def test_stored_reference_is_current(data, materials):
    test_accuracy.assert_stored_reference_current(data, materials, [("sunset", "paint"), ("studio", "coated"),
                                                                    ("forest", "metal")], np.arange(5, 2000, 125))


@pytest.mark.parametrize("preset", ["draft", "default", "high"])
def test_relative_rmse_within_preset_bounds(preset, data, materials):
    test_accuracy.assert_within_bounds(preset, preset_errors(preset, data, materials), BOUNDS, data,
                                       len(materials))


def test_higher_presets_are_more_accurate(data, materials):
    draft, default, high = (preset_errors(p, data, materials) for p in ("draft", "default", "high"))
    for name in materials:
        median = [np.median([e[k] for k in e if k[1] == name]) for e in (draft, default, high)]
        assert median[0] > median[1] > median[2], (name, median)
