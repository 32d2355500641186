"""Device code the kernels share: winner keys, block barriers, shared memory words, warp intrinsics, and the barrier
of the CPU cores.

Winner keys pack (distance bits << 32 | neuron index) into one uint64: distances are non-negative floats, whose
bit patterns order like the values, so the smallest key is the nearest neuron with the lowest index on a tie.
"""

import ctypes

import warp as wp

UNREACHABLE = wp.constant(wp.uint16(65535))
KEY_NONE = wp.constant(wp.uint64(0xFFFFFFFFFFFFFFFF))
INDEX_MASK = wp.constant(wp.uint64(0xFFFFFFFF))
FLOAT_MAX = wp.constant(wp.float32(3.4028234663852886e38))


@wp.func_native("union { float f; uint32_t u; } c; c.f = x; return c.u;")
def float_bits(x: wp.float32) -> wp.uint32: ...


@wp.func_native("union { float f; uint32_t u; } c; c.u = x; return c.f;")
def bits_float(x: wp.uint32) -> wp.float32: ...


@wp.func
def winner_key(distance: wp.float32, v: int) -> wp.uint64:
    return (wp.uint64(float_bits(distance)) << wp.uint64(32)) | wp.uint64(v)


@wp.func_native("""
#if defined(__CUDA_ARCH__)
return 0;
#else
long long ticket = __atomic_add_fetch(&counter[0], 1LL, __ATOMIC_ACQ_REL);
long long target = ((ticket - 1) / parties + 1) * parties;
for (long long spins = 0; __atomic_load_n(&counter[0], __ATOMIC_ACQUIRE) < target; ++spins) {
    if (spins < 2000 || yield_address == 0) {
#if defined(__x86_64__) || defined(__i386__)
        __builtin_ia32_pause();
#endif
    } else {  /* the other core is busy elsewhere: give this one away */
        typedef signed (*yield_fn)(void);  /* signed = int: Warp defines a macro int(x) */
        ((yield_fn)yield_address)();
    }
    if (spins > 50000000LL) return 1;  /* tens of seconds of yields: a core is gone, not just late */
}
return 0;
#endif
""")
def wait_for_cores(counter: wp.array(dtype=wp.int64), parties: wp.int64, yield_address: wp.uint64) -> int: ...


@wp.kernel(enable_backward=False)
def barrier(
    counter: wp.array(dtype=wp.int64), parties: wp.int64, yield_address: wp.uint64, failed: wp.array(dtype=wp.int32)
) -> None:
    """All CPU cores of a run meet here between the phases of a cycle. Real atomics (Warp's CPU ones are plain);
    after a short spin a waiting core calls yield_address (libc's sched_yield) so a busy machine is not starved.
    Once a core has given up waiting, every later meeting is skipped, so the run ends and the host reports it."""
    if failed[0] != 0:
        return
    if wait_for_cores(counter, parties, yield_address) != 0:
        failed[0] = 1


def sched_yield_address() -> int:
    """Address of libc's sched_yield, or 0 where there is none (then the barrier only spins)."""
    try:
        return ctypes.cast(ctypes.CDLL(None).sched_yield, ctypes.c_void_p).value or 0
    except (AttributeError, OSError, TypeError):
        return 0


# A barrier of the threads of a block: __syncthreads() on CUDA; on the CPU nothing (a block is one thread) or, with
# wp.config.enable_cpu_blocks, a switch between the block's cooperative fibers.
@wp.func_native("WP_TILE_SYNC();")
def sync_block() -> None: ...


# Programmatic dependent launch (see dependent_launch.py): a kernel so launched may start before the one before it
# ends; it waits here before reading what that kernel writes. A no-op for an ordinary launch, and on the CPU.
@wp.func_native("#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900\n"
                'asm volatile("griddepcontrol.wait;" ::: "memory");\n#endif\n')
def wait_for_previous_grid() -> None: ...


# -- a row search with its visited set and frontier in shared memory (CUDA) -------------------------------------
# A block's dynamic shared memory, reserved by one int32 tile (the kernel's only one, so it starts at offset 0),
# read and written by word index: the visited bitmap takes compare-free atomic ORs, the level counts atomic adds.
_SHARED = "extern __shared__ char dynamic_smem_base[]; "


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return atomicOr(((unsigned int*)dynamic_smem_base) + word, bits);\n#else\nreturn 0;\n#endif\n")
def shared_or(word: int, bits: wp.uint32) -> wp.uint32: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return atomicAdd(((int*)dynamic_smem_base) + word, value);\n#else\nreturn 0;\n#endif\n")
def shared_add(word: int, value: int) -> int: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return ((int*)dynamic_smem_base)[word];\n#else\nreturn 0;\n#endif\n")
def shared_get(word: int) -> int: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "((int*)dynamic_smem_base)[word] = value;\n#endif\n")
def shared_set(word: int, value: int) -> None: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED + "((float*)dynamic_smem_base)[word] = value;\n#endif\n")
def shared_set_float(word: int, value: wp.float32) -> None: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\n" + _SHARED
                + "return ((float*)dynamic_smem_base)[word];\n#else\nreturn 0.0f;\n#endif\n")
def shared_get_float(word: int) -> wp.float32: ...


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn __syncthreads_or(value);\n#else\nreturn value;\n#endif\n")
def sync_block_any(value: int) -> int:
    """A block barrier that also returns whether any thread passed a non-zero value."""
    ...


@wp.func_native("""
#if defined(__CUDA_ARCH__)
#if __CUDA_ARCH__ >= 800
unsigned int least = __reduce_min_sync(0xffffffffu, bits);
#else
unsigned int least = bits;
for (int offset = 16; offset > 0; offset >>= 1) least = min(least, __shfl_xor_sync(0xffffffffu, least, offset));
#endif
unsigned int lane = __ffs(__ballot_sync(0xffffffffu, bits == least)) - 1;
return ((unsigned long long)least << 32) | (unsigned long long)(first + (int)lane);
#else
return 0;
#endif
""")
def warp_least_key(bits: wp.uint32, first: int) -> wp.uint64:
    """The smallest winner key of a warp whose lane i holds the distance bits of neuron first + i: the lowest
    lane among equal distances, so the lowest index (lanes past the mesh repeat its last neuron). CUDA only."""
    ...


@wp.func_native("#if defined(__CUDA_ARCH__)\nreturn __shfl_sync(0xffffffffu, value, lane);\n"
                "#else\nreturn value;\n#endif\n")
def warp_shuffle(value: int, lane: int) -> int:
    """`value` of lane `lane` of the warp (CUDA; every lane must take part)."""
    ...


# Programmatic dependent launch (see dependent_launch.py): from here on the next kernel in the stream may be launched;
# it still waits in wait_for_previous_grid until this one has ended and its writes are visible.
@wp.func_native("#if defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 900\n"
                'asm volatile("griddepcontrol.launch_dependents;" ::: "memory");\n#endif\n')
def let_next_grid_launch() -> None: ...
