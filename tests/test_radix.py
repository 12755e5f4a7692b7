"""The radix sort under own.sap and own.bvh: the same order as numpy's stable sort."""

import numpy as np
from hypothesis import given
from hypothesis import strategies as st
from hypothesis.extra.numpy import arrays

from own.radix import radix_argsort, sortable_bits
from tiers import examples

FINITE = st.floats(allow_nan=False, allow_infinity=False, allow_subnormal=True)


@examples(200)
@given(arrays(np.float64, st.integers(0, 300), elements=FINITE | st.sampled_from([0.0, -0.0, 1.0, -1.0])))
def test_float_keys_sort_as_the_floats_do(values):
    order = radix_argsort(sortable_bits(values))
    assert np.array_equal(np.sort(order), np.arange(len(values)))
    assert (np.diff(values[order]) >= 0).all()
    # Stable among equal values (-0.0 sorts just before 0.0, which compare equal).
    expected = np.lexsort((np.arange(len(values)), np.signbit(values) & (values == 0) ^ 1, values))
    assert np.array_equal(order, expected)


@examples(200)
@given(arrays(np.uint64, st.integers(0, 300), elements=st.integers(0, 2**64 - 1) | st.integers(0, 7)))
def test_integer_keys_match_a_stable_argsort(keys):
    assert np.array_equal(radix_argsort(keys), np.argsort(keys, kind="stable"))


def test_large_inputs_take_every_pass():
    keys = np.random.default_rng(0).integers(0, 2**63, 5000, dtype=np.uint64) * np.uint64(2)
    assert np.array_equal(radix_argsort(keys), np.argsort(keys, kind="stable"))
