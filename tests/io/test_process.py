import numpy as np

from synth.io.process import return_freed_memory, rss_mb


def test_freed_small_arrays_leave_resident_memory():
    keep, drop = [], []
    for i in range(60_000):  # interleaved, so the dropped ones leave holes the heap cannot shrink past
        (keep if i % 8 == 0 else drop).append(np.full(200, i, np.float64))  # 1.6 kB each: heap, not mmap
    drop.clear()
    before = rss_mb()
    assert return_freed_memory()  # glibc (the project runs on Linux)
    after = rss_mb()
    assert after < before - 20, (before, after)  # ~ 52,500 x 1.6 kB were freed
    assert all(int(a[0]) == 8 * n for n, a in enumerate(keep))  # what is kept is untouched
