"""The records' total order (pipeline/store/records.sort_records, an LSD radix sort over 16-bit
digits) equals its definition (sort_records_reference: one lexsort over element, category, b1, b2
and the energy bits): groups of one and of two 16-bit digits, small and large batches, with and
without ties (where the energy bits' six digits join the sort)."""
from __future__ import annotations

import numpy as np
import pytest

from pipeline.store.records import (
    ELEMENT_BITS,
    ELEMENT_MASK,
    category_counts,
    element_grouped,
    pack_key,
    sort_records,
    sort_records_reference,
)


def _batch(n, n_elements, seed, *, bary_levels=65536, energy_levels=None):
    rng = np.random.default_rng(seed)
    key = rng.integers(0, n_elements, n).astype(np.uint32) | (rng.integers(0, 4, n).astype(np.uint32)
                                                              << np.uint32(ELEMENT_BITS))
    bary = rng.integers(0, bary_levels, (n, 2)).astype(np.uint16)
    energy = rng.random((n, 3)).astype(np.float32)
    if energy_levels:  # few distinct energies: whole records repeat
        energy = (rng.integers(0, energy_levels, (n, 1)) * np.ones((1, 3))).astype(np.float32)
    return key, bary, energy


@pytest.mark.parametrize("n, n_elements, bary_levels, energy_levels, path", [
    (5_000, 5_464, 65536, None, "one group digit"),          # element 13 bits + category 2
    (200_000, 5_464, 65536, None, "one group digit, large"),
    (200_000, 5_464, 4, None, "ties"),                       # (element, category, b1, b2) repeat
    (200_000, 5_464, 4, 3, "equal records"),                 # whole records repeat
    (3_000, 1 << 29, 65536, None, "two group digits"),       # 29 + 2 bits: two 16-bit digits
    (3_000, 1 << 29, 2, 2, "two group digits, ties"),
    (3_000, 3, 8, 2, "few elements, ties"),
])
def test_the_fast_order_is_the_defined_order(n, n_elements, bary_levels, energy_levels, path):
    key, bary, energy = _batch(n, n_elements, n + n_elements, bary_levels=bary_levels,
                               energy_levels=energy_levels)
    if path.startswith("two group digits"):
        key[:1000] = key[0]  # one group of 1,000 records
    got = sort_records(key, bary, energy)
    want = sort_records_reference(key, bary, energy)
    assert got.dtype == np.int64 and np.array_equal(got, want)


def test_the_order_does_not_depend_on_the_input_order():
    key, bary, energy = _batch(150_000, 5_464, 7, bary_levels=16, energy_levels=4)
    shuffle = np.random.default_rng(1).permutation(len(key))
    a = sort_records(key, bary, energy)
    b = sort_records(key[shuffle], bary[shuffle], energy[shuffle])
    for x in (key, bary, energy):
        assert np.array_equal(x[a], x[shuffle][b])


@pytest.mark.parametrize("n_elements", [1, 5300, 70_000])
def test_element_grouping_keeps_the_writers_order_within_an_element(n_elements):
    """element_grouped (a radix sort on the element id's 16-bit digits) is numpy's stable argsort of
    the element ids; category_counts is the per-(category, element) bincount."""
    rng = np.random.default_rng(n_elements)
    n = 50_000
    key = pack_key(rng.integers(0, n_elements, n), rng.integers(0, 1 << 20, n), rng.random(n) < 0.3)
    bary = rng.integers(0, 65535, (n, 2)).astype(np.uint16)
    energy = rng.random((n, 3)).astype(np.float32)
    element = key & np.uint32(ELEMENT_MASK)
    order = np.argsort(element, kind="stable")
    k, b, e, offsets = element_grouped(key, bary, energy, n_elements)
    assert np.array_equal(k, key[order]) and np.array_equal(b, bary[order]) and np.array_equal(e, energy[order])
    assert np.array_equal(np.diff(offsets), np.bincount(element, minlength=n_elements))
    want = np.zeros((4, n_elements), np.uint64)
    np.add.at(want, ((key >> np.uint32(30)).astype(np.intp), element.astype(np.intp)), 1)
    assert np.array_equal(category_counts(key, n_elements), want)
    # with_counts: the same grouping, and the counts from the bincount that gave the offsets
    *again, counts = element_grouped(key, bary, energy, n_elements, with_counts=True)
    assert all(np.array_equal(x, y) for x, y in zip(again, (k, b, e, offsets)))
    assert np.array_equal(counts, want) and counts.dtype == np.uint64
