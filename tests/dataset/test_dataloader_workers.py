"""Tar datasets through ``torch.utils.data.DataLoader`` with 2 workers (docs/reading.md,
"DataLoader workers"): the documented pattern yields every frame exactly once, also with fewer
shards than workers; the two pitfalls it avoids are shown failing."""

from __future__ import annotations

from collections import Counter

import pytest

from synth.dataset.reader import by_worker, decode_sample, iter_frames, list_frames
from synth.dataset.tarshard import tar_path
from tests.dataset.test_tarshard import make
from tests.support import fake_frames as ff

wds = pytest.importorskip("webdataset")
torch = pytest.importorskip("torch")
from torch.utils.data import DataLoader, IterableDataset  # noqa: E402

ONE_SHARD = ff.plan(n_shards=1, n_expr=2, n_views=3)  # 6 frames, fewer shards than workers
THREE_SHARDS = ff.plan(n_shards=3, n_expr=1, n_views=3)  # 9 frames, one more shard than workers


def fingerprint(frame) -> tuple[str, float]:
    """What crosses from a worker: the key and a checksum of the decoded pixels."""
    return frame.key, float(frame.rgba.astype("float64").sum())


def loader(ds) -> Counter:
    return Counter(tuple(x) for x in DataLoader(ds, batch_size=None, num_workers=2))  # tuples come back as lists


@pytest.fixture(scope="module", params=[ONE_SHARD, THREE_SHARDS], ids=["1-shard", "3-shards"])
def tars(request, tmp_path_factory):
    root = make(tmp_path_factory.mktemp("wds") / "ds", "tar", plan=request.param)
    urls = [str(tar_path(root, s)) for s in sorted(request.param)]
    return root, urls, Counter(fingerprint(f) for f in iter_frames(root))


def test_split_by_sample_gives_every_frame_once(tars):
    """The documented pattern: each worker reads every shard, keeps every second sample
    (by_worker) and decodes only those."""
    _, urls, want = tars
    ds = (wds.WebDataset(urls, shardshuffle=False, workersplitter=None, empty_check=False)
          .compose(by_worker).map(decode_sample).map(fingerprint))
    got = loader(ds)
    assert got == want and set(got.values()) == {1}


def test_split_by_shard_without_empty_check_gives_every_frame_once(tars):
    """WebDataset's own split by shard is exact too once empty_check is off (a worker without a
    shard yields nothing); with one shard it decodes on one worker only."""
    _, urls, want = tars
    ds = wds.WebDataset(urls, shardshuffle=False, empty_check=False).map(decode_sample).map(fingerprint)
    assert loader(ds) == want


def test_reader_refs_in_an_iterable_dataset_give_every_frame_once(tars):
    root, _, want = tars

    class Frames(IterableDataset):
        def __iter__(self):
            for ref in by_worker(list_frames(root)):
                yield fingerprint(ref.read())

    assert loader(Frames()) == want
    assert list(by_worker(range(5))) == list(range(5))  # outside a worker: everything


def test_the_pitfalls(tars):
    _, urls, want = tars
    if len(urls) < 2:  # default split by shard: the worker without a shard raises
        with pytest.raises(ValueError, match="No samples found"):
            loader(wds.WebDataset(urls, shardshuffle=False).map(decode_sample).map(fingerprint))
    # no split at all: every worker reads everything
    dup = loader(wds.WebDataset(urls, shardshuffle=False, workersplitter=None).map(decode_sample).map(fingerprint))
    assert dup == Counter({k: 2 * n for k, n in want.items()})
