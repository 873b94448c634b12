"""glibc's heap kept for ptwin's tensors (``ptwin.heap``): a large block comes from the heap, not a mapping of its
own, and stays in the heap when freed. Each case in a fresh interpreter: the thresholds are the process's."""

import ctypes
import subprocess
import sys
from pathlib import Path

import pytest

import ptwin.heap

BLOCK = 30 * 2**20  # below glibc's largest mmap threshold, above any a fresh process has reached

# Prints where a block of BLOCK bytes came from and where its memory went when freed, with the heap kept or not.
# The module is run from its file, not imported with the package, whose import would take torch's second.
PROBE = f"""
import ctypes, runpy, sys
keep_heap = runpy.run_path({str(Path(ptwin.heap.__file__))!r})["keep_heap"]
class Info(ctypes.Structure):
    _fields_ = [(name, ctypes.c_size_t) for name in
                "arena ordblks smblks hblks hblkhd usmblks fsmblks uordblks fordblks keepcost".split()]
libc = ctypes.CDLL("libc.so.6")
libc.mallinfo2.restype, libc.malloc.restype = Info, ctypes.c_void_p
if sys.argv[1] == "kept":
    keep_heap()
mapped = libc.mallinfo2().hblkhd
block = libc.malloc({BLOCK})
ctypes.memset(block, 1, {BLOCK})
print(libc.mallinfo2().hblkhd - mapped >= {BLOCK})
libc.free(ctypes.c_void_p(block))
print(libc.mallinfo2().fordblks >= {BLOCK})
"""


def probed(mode: str) -> tuple[bool, bool]:
    """(whether the block was mapped on its own, whether its memory stayed in the heap once freed)."""
    out = subprocess.run([sys.executable, "-c", PROBE, mode], capture_output=True, text=True, check=True).stdout
    mapped, stayed = out.split()
    return mapped == "True", stayed == "True"


def glibc_with_mallinfo2() -> bool:
    try:
        return hasattr(ctypes.CDLL("libc.so.6"), "mallinfo2")
    except OSError:
        return False


@pytest.mark.skipif(not glibc_with_mallinfo2(), reason="needs glibc ≥ 2.33 (mallinfo2) to see where a block lies")
def test_a_large_block_comes_from_the_heap_and_stays_there_when_freed():
    if probed("default") != (True, False):
        pytest.skip("this glibc serves such a block from its heap without being asked: nothing to tell apart")
    assert probed("kept") == (False, True)
