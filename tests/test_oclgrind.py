"""The kernels on Oclgrind, a simulated OpenCL device that reports out-of-bounds accesses, data
races and API misuse (``tests/oclgrind_check.py``; ``make check-kernels`` runs every kernel
file's tests on it). Here a small slice of them, and the proof that the check can fail: a tiny
kernel written below that writes past its buffer, one that races in local memory, and a read
past a buffer's end that pyopencl refuses must each be reported and fail their test. Oclgrind
is Debian's ``oclgrind`` (``make test`` installs it): a missing one fails, it does not skip."""

from oclgrind_check import oclgrind, run_pytest

BAD_KERNELS = '''
import numpy as np
import pyopencl as cl
import pytest

SOURCE = """
__kernel void past_the_end(__global float *x)     // x holds get_global_size(0) floats
{
    x[get_global_id(0) + 1] = 1.0f;               // the last work-item writes one past the end
}

__kernel void racing(__global int *out)           // one work-group; out holds one int per work-item
{
    __local int shared;
    shared = (int)get_local_id(0);                // every work-item a different value, no barrier
    barrier(CLK_LOCAL_MEM_FENCE);
    out[get_global_id(0)] = shared;
}

__kernel void in_bounds(__global float *x)
{
    x[get_global_id(0)] = 1.0f;
}
"""


@pytest.fixture(scope="module")
def cl_env():
    platform, = cl.get_platforms()                # the oclgrind command leaves only its own
    assert platform.name == "Oclgrind"
    context = cl.Context(platform.get_devices())
    return context, cl.CommandQueue(context), cl.Program(context, SOURCE).build()


def run(cl_env, name, dtype):
    context, queue, program = cl_env
    host = np.zeros(4, dtype)
    buf = cl.Buffer(context, cl.mem_flags.READ_WRITE, host.nbytes)
    kernel = cl.Kernel(program, name)
    kernel.set_arg(0, buf)
    cl.enqueue_nd_range_kernel(queue, kernel, (4,), (4,))
    cl.enqueue_copy(queue, host, buf)
    return host


def test_out_of_bounds(cl_env):
    run(cl_env, "past_the_end", np.float32)


def test_race(cl_env):
    run(cl_env, "racing", np.int32)


def test_api_misuse(cl_env):                       # passes by itself: only the report fails it
    context, queue, _ = cl_env
    buf = cl.Buffer(context, cl.mem_flags.READ_WRITE, 16)
    with pytest.raises(cl.LogicError):
        cl.enqueue_copy(queue, np.zeros(8, np.float32), buf)      # 32 bytes from a 16-byte buffer


def test_clean(cl_env):
    assert (run(cl_env, "in_bounds", np.float32) == 1).all()
'''


def test_out_of_bounds_a_data_race_and_api_misuse_are_reported_and_fail(tmp_path):
    oclgrind()
    (tmp_path / "test_bad_kernels.py").write_text(BAD_KERNELS)
    result = run_pytest(["-q", "test_bad_kernels.py"], cwd=tmp_path, echo=False)
    by_test = {test.rpartition("::")[2]: found for test, found in result["reports"].items()}
    assert (result["tests"], result["passed"], result["failed"]) == (4, 1, 3), result["output"]
    assert sorted(by_test) == ["test_api_misuse", "test_out_of_bounds", "test_race"] and not result["stray"], result
    oob, = by_test["test_out_of_bounds"]
    assert oob.startswith("Invalid write of size 4 at global memory address") and "Kernel: past_the_end" in oob
    races = by_test["test_race"]                  # one per work-item racing with work-item 0
    assert len(races) == 3 and all(r.startswith("Write-write data race at local memory address")
                                   and "Kernel: racing" in r for r in races)
    api, = by_test["test_api_misuse"]
    assert api.startswith("Oclgrind - OpenCL runtime error detected") and "Function: clEnqueueReadBuffer" in api
    assert "Oclgrind reported 1 problem(s) during call" in result["output"]      # the failure says why


def test_kernel_tests_run_clean_under_oclgrind():
    """CFAR on the CPU paths (every vector width, in partial work-groups of 7) and the interpreter
    as a 32 KiB GPU, at small sizes: no report."""
    oclgrind()
    for test_file, select, limits in [("tests/test_cfar.py", "test_local_sizes_and_vector_widths_agree and 7", None),
                                      ("tests/test_interpret.py", "test_matches_oracle or test_local_sizes_agree",
                                       "gpu-32k")]:
        result = run_pytest(["-q", test_file, "-k", select], limits=limits, echo=False)
        assert result["tests"] >= 3 and result["exit"] == 0, result["output"]
        assert not result["reports"] and not result["stray"], result
