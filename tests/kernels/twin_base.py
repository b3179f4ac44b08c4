"""A shared conformance suite for OpenCL kernels against their NumPy twins.

In the style of zarr-python's ``StoreTests``: :class:`KernelTwinTests` holds the generic tests, and
each kernel's test module subclasses it (the subclass's name must start with ``Test``) and says

* ``cases``: names of the input cases, mapped to whatever :meth:`make_inputs` needs to build them.
  Include edge cases: 0 and 1 elements, and sizes that are not a multiple of the work-group or of the
  lanes (``LANES`` = 8 rays a work item, ``WORK_GROUP`` = 64 items, kernels/context.py);
* :meth:`make_inputs`: the positional arguments of one case, built from the seeded ``rng`` fixture;
* :meth:`device` and :meth:`twin`: the OpenCL path and its NumPy reference, called with those
  arguments (these three are abstract: a subclass without one cannot run);
* the comparison rule: ``rtol`` and ``atol`` (both 0, the default, means bit-identical), per output
  through :meth:`rule` where outputs differ (integers exact, floats to a tolerance);
* :meth:`outputs` when a result is not an array, a tuple of arrays or a dataclass of arrays.

The base then runs, on every case: agreement of device and twin under the rule, determinism (two
device runs give the same bytes), and equal output names, shapes and dtypes. Two self-checks make
sure the suite can fail: the cases must exercise the kernel (some output non-empty and not
constant), and the rule must reject a twin output perturbed beyond its tolerance.
"""
from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from typing import Any, ClassVar

import numpy as np
import pytest


def _paired(a: dict, b: dict):
    """(name, a[name], b[name]) for the outputs both sides have as arrays; both must have the same
    names and agree on which are None."""
    assert a.keys() == b.keys(), f"outputs {sorted(a)} against {sorted(b)}"
    for name, x in a.items():
        y = b[name]
        assert (x is None) == (y is None), f"{name}: one side is None"
        if x is not None:
            yield name, x, y


class KernelTwinTests(ABC):
    """Generic kernel-versus-twin tests; subclass per kernel (see the module docstring)."""

    cases: ClassVar[dict[str, Any]] = {}
    rtol: ClassVar[float] = 0.0
    atol: ClassVar[float] = 0.0

    # --- hooks ---------------------------------------------------------------------------------

    @abstractmethod
    def make_inputs(self, rng: np.random.Generator, case: Any) -> tuple:
        """The positional arguments of :meth:`device` and :meth:`twin` for one case."""

    @abstractmethod
    def device(self, *args):
        """The OpenCL path."""

    @abstractmethod
    def twin(self, *args):
        """The NumPy reference."""

    def rule(self, name: str, want: np.ndarray) -> tuple[float, float]:
        """(rtol, atol) for output ``name`` whose twin value is ``want``; (0, 0) is bit-identical."""
        return self.rtol, self.atol

    def outputs(self, result) -> dict[str, np.ndarray | None]:
        """Named copies of a result's arrays (copies: some wrappers reuse their output arrays)."""
        if dataclasses.is_dataclass(result):
            items = [(f.name, getattr(result, f.name)) for f in dataclasses.fields(result)]
        elif isinstance(result, tuple):
            items = [(str(i), a) for i, a in enumerate(result)]
        else:
            items = [("out", result)]
        return {name: None if a is None else np.array(a, copy=True) for name, a in items}

    # --- comparison ----------------------------------------------------------------------------

    def compare(self, got: dict, want: dict) -> None:
        """Assert that device outputs ``got`` agree with twin outputs ``want`` under the rule."""
        assert got.keys() == want.keys(), f"outputs {sorted(got)} against the twin's {sorted(want)}"
        for name, w in want.items():
            g = got[name]
            if w is None or g is None:
                assert g is None and w is None, f"{name}: one side is None"
                continue
            assert g.shape == w.shape, f"{name}: shape {g.shape} against the twin's {w.shape}"
            rtol, atol = self.rule(name, w)
            if rtol == 0 and atol == 0:
                np.testing.assert_array_equal(g, w, err_msg=name)
            else:
                np.testing.assert_allclose(g, w, rtol=rtol, atol=atol, err_msg=name)

    def _run(self, rng, case_name):
        args = self.make_inputs(rng, self.cases[case_name])
        return args, self.outputs(self.device(*args)), self.outputs(self.twin(*args))

    # --- the tests -----------------------------------------------------------------------------

    def pytest_generate_tests(self, metafunc):
        if "case_name" in metafunc.fixturenames:
            metafunc.parametrize("case_name", list(self.cases))

    def test_device_agrees_with_twin(self, rng, case_name):
        _, got, want = self._run(rng, case_name)
        self.compare(got, want)

    def test_device_is_deterministic(self, rng, case_name):
        args = self.make_inputs(rng, self.cases[case_name])
        first = self.outputs(self.device(*args))
        again = self.outputs(self.device(*args))
        for name, a, b in _paired(first, again):
            assert a.shape == b.shape and a.tobytes() == b.tobytes(), f"{name} differs between two runs"

    def test_outputs_have_the_twins_shapes_and_dtypes(self, rng, case_name):
        _, got, want = self._run(rng, case_name)
        for name, g, w in _paired(got, want):
            assert (g.shape, g.dtype) == (w.shape, w.dtype), name

    def test_cases_exercise_the_kernel(self, rng):
        """Some case gives a non-empty output that is not constant (all-zero cases prove nothing)."""
        assert self.cases, "no cases"
        for case_name in self.cases:
            want = self.outputs(self.twin(*self.make_inputs(rng, self.cases[case_name])))
            if any(w is not None and w.size > 1 and np.unique(w).size > 1 for w in want.values()):
                return
        pytest.fail("every case gives empty or constant outputs")

    def test_rule_rejects_a_perturbed_output(self, rng):
        """The comparison fails when one element of one output moves beyond the tolerance."""
        name_of_largest = max(self.cases, key=lambda c: sum(
            w.size for w in self.outputs(self.twin(*self.make_inputs(rng, self.cases[c]))).values()
            if w is not None))
        want = self.outputs(self.twin(*self.make_inputs(rng, self.cases[name_of_largest])))
        checked = 0
        for name, w in want.items():
            if w is None or w.size == 0:
                continue
            bad = {k: None if v is None else v.copy() for k, v in want.items()}
            flat = bad[name].reshape(-1)
            i = flat.size // 2
            rtol, atol = self.rule(name, w)
            if flat.dtype == bool:
                flat[i] = ~flat[i]
            elif np.issubdtype(flat.dtype, np.integer):
                flat[i] = flat[i] - 1 if flat[i] > np.iinfo(flat.dtype).min else flat[i] + 1
            else:
                step = 10 * (atol + rtol * abs(float(flat[i]))) + 10 * np.finfo(flat.dtype).eps * (
                    1 + abs(float(flat[i])))
                flat[i] = flat[i] + step if np.isfinite(flat[i]) else 0
            with pytest.raises(AssertionError):
                self.compare(bad, want)
            checked += 1
        assert checked, "the largest case has no non-empty output"
