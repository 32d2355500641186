"""The raw-pointer parameters of the spread cycle kernels (spread_kernels.spread_cycle_inputs and
spread_smoothing_cycle_inputs): each pointer and size in the kernel's order, and a clear error for an array the
kernels cannot read as a plain block of memory. Runs on the CPU: nothing here launches a kernel."""

from __future__ import annotations

import pytest
import warp as wp

from somwidget.backend.spread_kernels import spread_cycle_inputs, spread_smoothing_cycle_inputs

N, K = 70, 5


def _arrays() -> dict:
    vec3 = wp.types.vector(length=3, dtype=wp.float32)
    return dict(
        weights_in=wp.zeros(N, dtype=vec3, device="cpu"), weights_out=wp.zeros(N, dtype=vec3, device="cpu"),
        controls=wp.zeros(256, dtype=vec3, device="cpu"), metric=wp.zeros(1, dtype=vec3, device="cpu"),
        table=wp.zeros((1000, 46), dtype=wp.float32, device="cpu"),
        distances=wp.zeros((N, N), dtype=wp.uint16, device="cpu"), slot_of=wp.zeros(N, dtype=wp.int32, device="cpu"),
        keys=wp.zeros((3, 256), dtype=wp.uint64, device="cpu"), cycle_in=wp.zeros(1, dtype=wp.int32, device="cpu"),
        cycle_out=wp.zeros(1, dtype=wp.int32, device="cpu"), stalled=wp.zeros(1, dtype=wp.int32, device="cpu"),
        listed=wp.zeros((3, 64), dtype=wp.int32, device="cpu"), local=wp.zeros((N, 4), dtype=wp.int32, device="cpu"),
        offsets=wp.zeros(N + 1, dtype=wp.int32, device="cpu"), mask=wp.zeros(1, dtype=vec3, device="cpu"),
    )


def test_spread_cycle_inputs_in_kernel_order():
    a = _arrays()
    got = spread_cycle_inputs(a["weights_in"], a["weights_out"], a["controls"], K, a["metric"], a["table"],
                              a["distances"], a["slot_of"], a["keys"], a["cycle_in"], a["cycle_out"], a["stalled"])
    assert got == [a["weights_in"].ptr, a["weights_out"].ptr, N, a["controls"].ptr, K, a["metric"].ptr,
                   a["table"].ptr, 1000, 46, a["distances"].ptr, N, a["slot_of"].ptr, a["keys"].ptr, 256,
                   a["cycle_in"].ptr, a["cycle_out"].ptr, a["stalled"].ptr]


def test_spread_smoothing_cycle_inputs_in_kernel_order():
    a = _arrays()
    got = spread_smoothing_cycle_inputs(a["weights_in"], a["weights_out"], a["controls"], K, a["metric"], a["table"],
                                        a["distances"], a["keys"], a["cycle_in"], a["cycle_out"], a["listed"],
                                        a["local"], a["offsets"], a["mask"], 0.25)
    assert got == [a["weights_in"].ptr, a["weights_out"].ptr, N, a["controls"].ptr, K, a["metric"].ptr,
                   a["table"].ptr, 1000, 46, a["distances"].ptr, a["keys"].ptr, 256, a["cycle_in"].ptr,
                   a["cycle_out"].ptr, a["listed"].ptr, 3, a["local"].ptr, a["offsets"].ptr, a["mask"].ptr, 0.25]


def test_a_strided_array_is_refused_by_name_of_its_layout():
    a = _arrays()
    every_other_key = a["keys"][:, ::2]
    with pytest.raises(ValueError, match=r"contiguous arrays; got one of shape \(3, 128\) and strides \(2048, 16\)"):
        spread_cycle_inputs(a["weights_in"], a["weights_out"], a["controls"], K, a["metric"], a["table"],
                            a["distances"], a["slot_of"], every_other_key, a["cycle_in"], a["cycle_out"], a["stalled"])
