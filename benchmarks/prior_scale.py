"""The prior's data path at scale: prepare pass, memory per rank, loader rays/s (docs/prior.md, "Scale").

Synthetic tar datasets are written through the project's own shard writer (StagingShard ->
commit, ``dataset.shard_format = "tar"``): N identities x 13 expressions x 30 views at 32^2,
the frames of ``tests/prior/scene.py`` (a shaded sphere per identity seen by ring cameras, 8
sphere sizes repeated; frame JSON with cameras, codes (identity 48), joint rotations and
landmarks). Files are not fsynced; everything else, the frame JSON check included, is the
writer's own path.

    python benchmarks/prior_scale.py write --identities 15 --out /tmp/scale15
    python benchmarks/prior_scale.py write --identities 1500 --views 2 --out /tmp/p1500   # a quick proxy:
        # the same identity table (13 expressions each) with 2 views per expression, written in ~7 min
    python benchmarks/prior_scale.py measure /tmp/scale15 --buffer 8 --ranks 1 2
    python benchmarks/prior_scale.py webdataset /tmp/scale15        # the plain WebDataset pipeline
    python benchmarks/prior_scale.py tools /tmp/scale15             # synth validate / report / index / resume
    python benchmarks/prior_scale.py train-rss /tmp/scale15 --buffer 4   # peak RSS of real training ranks

``measure`` runs, each in fresh processes: the prepare pass (into a new directory; time and peak
RSS), then per rank (1 and 2 ranks; 2 run at once) the run's setup path: the table from the
records, a loader with ``--buffer`` identities, time to the first batch, and the loader's rays/s
(``small`` batch shape 2 x 4 x 128 split over the ranks, then the paper's 256 x 8 x 64) with
identities swapped in and out (``--views-per-load``, default 1: an identity leaves the buffer
after as many views as it has frames), and the rank's peak RSS.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

EXPRESSIONS, VIEWS, SIZE = 13, 30, 32


def write(out: Path, identities: int, views: int = VIEWS) -> None:
    if "numpy" not in sys.modules:  # the scene's 4x4 inverses: OpenBLAS threads only spin on a busy machine
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    from synth.dataset.shards import open_dataset
    from tests.prior import scene
    from tests.support import fake_frames as ff

    expected = {f"shard_{i:06d}": [ff.frame_key(i, e, v) for e in range(EXPRESSIONS) for v in range(views)]
                for i in range(identities)}
    ds = open_dataset(out, "b" * 64, expected, shard_format="tar")
    t0 = time.perf_counter()
    for sid in ds.pending_shards():
        with ds.staging(sid) as st:
            for key in expected[sid]:
                i, e, v = ff.parse_frame_key(key)
                # the scene's sphere grows with the identity index: 8 sizes, repeated
                _, px, meta = scene.frame(i % 8, e, v, views, SIZE, id_size=48)
                meta.update(frame_id=key, identity_index=i)
                meta["image"]["file"] = f"{key}.exr"
                meta["model"]["identity"] = [0.01 * i + 0.05 * k for k in range(48)]
                st.write_frame(key, *px, meta, durable=False)
            st.commit(manifest_extra={"seeds": {"run": 0}, "versions": {"blender": "none"}}, durable=False)
    n = identities * EXPRESSIONS * views
    print(f"wrote {identities} identities, {n} frames in {time.perf_counter() - t0:.0f} s", flush=True)


def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def prepare_child(ds: str, out: str, workers: int) -> None:
    from prior.data import build_table, open_source, prepare

    t0 = time.perf_counter()
    src = open_source(ds)
    res = prepare(src, Path(out), workers=workers)
    t = build_table(res, joints=("jaw", "eye_l", "eye_r"), margin=0.05, planned=src.planned_identities)
    dt = time.perf_counter() - t0
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(json.dumps({"prepare_s": dt, "frames": int(t.frames.sum()), "written": res.written,
                      "peak_rss_mb": _peak_mb(), "worker_peak_rss_mb": kids}))


def rank_child(ds: str, prep: str, rank: int, world: int, buffer: int, steps: int, reuse: float) -> None:
    import numpy as np

    from prior.data import Loader, RaySampler, build_table, open_source, prepare
    from prior.data.prepare import trim_heap

    t0 = time.perf_counter()
    src = open_source(ds)
    table = build_table(prepare(src, Path(prep), write_merged=False), joints=("jaw", "eye_l", "eye_r"), margin=0.05,
                        planned=src.planned_identities)
    trim_heap()  # as training does (prior.train.run.prepare)
    ld = Loader(src, table, seed=0, rank=rank, world=world, buffer_identities=buffer, views_per_load=reuse,
                read_ahead=2, prepare_dir=Path(prep))
    ld.start()
    per = max(2 // world, 1)
    s = RaySampler(ld, seed=0, identities=per, views=4, pixels=128, foreground_fraction=0.5, rank=rank)
    s.batch(0)
    s.step_done()
    first = time.perf_counter() - t0
    t1 = time.perf_counter()
    for step in range(1, steps + 1):
        s.batch(step)
        s.step_done()
    dt = time.perf_counter() - t1
    rays = steps * s.rays_per_batch
    paper = RaySampler(ld, seed=0, identities=256 // world, views=8, pixels=64, foreground_fraction=0.5, rank=rank)
    paper.batch(0)
    times = []
    for step in range(1, 4):
        t2 = time.perf_counter()
        paper.batch(step)
        times.append(time.perf_counter() - t2)
        paper.drawn = []
    held = ld.nbytes
    ld.close()
    print(json.dumps({"rank": rank, "world": world, "first_batch_s": first, "rays_per_s": rays / dt,
                      "swapped_epochs": ld.epoch, "paper_batch_rays": paper.rays_per_batch,
                      "paper_batch_s": float(np.median(times)), "buffer_mb": held / 2**20, "peak_rss_mb": _peak_mb()}))


def _child(args: list[str]) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1"}
    return subprocess.Popen([sys.executable, __file__, *args], stdout=subprocess.PIPE, text=True, env=env)


def measure(ds: Path, buffer: int, ranks: list[int], steps: int, workers: int, reuse: float) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        prep = str(Path(tmp) / "prepare")
        p = _child(["_prepare", str(ds), prep, str(workers)])
        r = json.loads(p.communicate()[0])
        print(f"| prepare | {r['frames']} frames | {r['prepare_s']:.1f} s | {r['frames'] / r['prepare_s']:.0f} "
              f"frames/s | peak RSS {r['peak_rss_mb']:.0f} MB (workers {r['worker_peak_rss_mb']:.0f} MB) |",
              flush=True)
        again = json.loads(_child(["_prepare", str(ds), prep, str(workers)]).communicate()[0])
        print(f"| prepare again (nothing new) | {again['written']} written | {again['prepare_s']:.2f} s |", flush=True)
        for world in ranks:
            procs = [_child(["_rank", str(ds), prep, str(r), str(world), str(buffer), str(steps), str(reuse)])
                     for r in range(world)]
            for q in procs:
                o = json.loads(q.communicate()[0])
                print(f"| {world} rank(s), rank {o['rank']} | buffer {buffer} | first batch {o['first_batch_s']:.1f} s "
                      f"| {o['rays_per_s']:,.0f} rays/s | paper batch {o['paper_batch_rays']:,} rays in "
                      f"{o['paper_batch_s']:.3f} s | buffer {o['buffer_mb']:.0f} MB | peak RSS {o['peak_rss_mb']:.0f} "
                      f"MB | epochs {o['swapped_epochs']} |", flush=True)


def train_rss(ds: Path, ranks: list[int], steps: int, buffer: int) -> None:
    """Peak RSS of each rank of a real ``synth prior train`` run (``small`` preset, gloo, one
    process per rank on this machine, a checkpoint at the end): what a training rank holds, with
    the allocator's state that training steps leave, which the loader-only ``measure`` lacks."""
    import socket

    with tempfile.TemporaryDirectory() as tmp:
        for world in ranks:
            with socket.socket() as sock:
                sock.bind(("127.0.0.1", 0))
                port = str(sock.getsockname()[1])
            run = Path(tmp) / f"run{world}"
            env = {**os.environ, "PYTHONPATH": str(ROOT), "OMP_NUM_THREADS": "1", "MASTER_ADDR": "127.0.0.1",
                   "MASTER_PORT": port, "WORLD_SIZE": str(world)}
            t0 = time.perf_counter()
            procs = [subprocess.Popen([sys.executable, "-m", "prior.cli", "train", str(ds), "--out", str(run),
                                       "--steps", str(steps), "--set", f"data.buffer_identities={buffer}"],
                                      env={**env, "RANK": str(r), "LOCAL_RANK": str(r)}, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.PIPE, text=True) for r in range(world)]
            peaks, codes, errs = [], [], []
            for q in procs:
                err = q.stderr.read()
                _, status, usage = os.wait4(q.pid, 0)
                q.returncode = os.waitstatus_to_exitcode(status)
                peaks.append(usage.ru_maxrss / 1024)
                codes.append(q.returncode)
                errs.append(err.strip().splitlines()[-1:] if q.returncode else [])
            ok = "ok" if codes == [0] * world else f"exit {codes}: {errs}"
            print(f"| {world} rank(s) | buffer {buffer} | {steps} steps in {time.perf_counter() - t0:.0f} s | peak RSS "
                  f"{' / '.join(f'{m:.0f}' for m in peaks)} MB | {ok} |", flush=True)


TOOLS = ("validate", "validate -j 1", "validate --quick", "report", "index rebuild", "resume planning")


def tool_child(name: str, ds: str) -> None:
    """One dataset tool on ``ds`` in this (fresh) process: its wall time and peak RSS."""
    t0 = time.perf_counter()
    if name.startswith("validate"):
        from synth.dataset.validate import validate_dataset
        from synth.io.process import default_jobs

        jobs = 1 if name.endswith("-j 1") else default_jobs()  # the CLI's default: up to 4 processes
        rep = validate_dataset(ds, quick=name.endswith("--quick"), partial=True, jobs=jobs)
        what = f"{rep.frames_checked} frames, {len(rep.defects)} defects, {jobs} process(es)"
    elif name == "report":
        from synth.report.html import write_report

        with tempfile.TemporaryDirectory() as tmp:
            summary = write_report(ds, Path(tmp) / "report.html")
        what = f"{summary['progress']['frames_committed']} frames"
    elif name == "index rebuild":
        from synth.dataset.validate_index import repair

        what = f"{len(repair(ds))} changes"
    else:  # what `synth render` does before it starts a worker on a dataset it resumes
        from renderer_jobs.submit import staged_frames
        from synth.dataset.shards import load_dataset, open_dataset

        ds0 = load_dataset(ds)
        ds0.summary()  # submit.finished: is everything committed?
        w = open_dataset(ds, ds0.plan_hash, ds0.expected, shard_format=ds0.shard_format)
        pending = w.pending_shards()
        what = f"{len(pending)} shards pending, {staged_frames(w, pending)} frames staged"
    kids = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    print(json.dumps({"tool": name, "s": time.perf_counter() - t0, "peak_rss_mb": max(_peak_mb(), kids),
                      "what": what}))


def tools(ds: Path) -> None:
    for name in TOOLS:
        o = json.loads(_child(["_tool", name, str(ds)]).communicate()[0])
        print(f"| {name} | {o['what']} | {o['s']:.1f} s | {o['peak_rss_mb']:.0f} MB |", flush=True)


def webdataset_pipeline(ds: Path, workers: int, limit: int) -> None:
    """Frames/s of a plain WebDataset + DataLoader over the same tar shards, decoding the same
    frames (synth.dataset.reader.decode_sample), against the project's reader (read_shard + decode)."""
    import torch.utils.data as tud
    import webdataset as wds

    from prior.data.sources import open_source, read_shard
    from synth.dataset.reader import decode_frame, decode_sample

    urls = sorted(str(p) for p in (ds / "shards").glob("*.tar"))
    pipe = wds.WebDataset(urls, shardshuffle=False, empty_check=False).map(lambda s: decode_sample(s).rgba.shape)
    loader = tud.DataLoader(pipe, batch_size=None, num_workers=workers)
    t0, n = time.perf_counter(), 0
    for _ in loader:
        n += 1
        if n >= limit:
            break
    wd = n / (time.perf_counter() - t0)
    t0, m = time.perf_counter(), 0
    for ref in open_source(ds).committed():
        for key, jb, eb in read_shard(ref):
            decode_frame(jb, eb, key=key)
            m += 1
            if m >= limit:
                break
        if m >= limit:
            break
    own = m / (time.perf_counter() - t0)
    print(f"| WebDataset + DataLoader ({workers} workers) | {wd:.0f} frames/s |\n"
          f"| project reader (read_shard + decode, 1 thread) | {own:.0f} frames/s |")


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "_prepare":
        return prepare_child(sys.argv[2], sys.argv[3], int(sys.argv[4]))
    if len(sys.argv) > 1 and sys.argv[1] == "_tool":
        return tool_child(sys.argv[2], sys.argv[3])
    if len(sys.argv) > 1 and sys.argv[1] == "_rank":
        return rank_child(sys.argv[2], sys.argv[3], *map(int, sys.argv[4:8]), float(sys.argv[8]))
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    w = sub.add_parser("write")
    w.add_argument("--identities", type=int, required=True)
    w.add_argument("--out", type=Path, required=True)
    w.add_argument("--views", type=int, default=VIEWS, help="views per expression (30: the paper's shape)")
    m = sub.add_parser("measure")
    m.add_argument("dataset", type=Path)
    m.add_argument("--buffer", type=int, default=8)
    m.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    m.add_argument("--steps", type=int, default=200)
    m.add_argument("--workers", type=int, default=2)
    m.add_argument("--views-per-load", type=float, default=1.0)
    b = sub.add_parser("webdataset")
    b.add_argument("dataset", type=Path)
    b.add_argument("--workers", type=int, default=1)
    b.add_argument("--frames", type=int, default=2000)
    t = sub.add_parser("tools")
    t.add_argument("dataset", type=Path)
    r = sub.add_parser("train-rss")
    r.add_argument("dataset", type=Path)
    r.add_argument("--ranks", type=int, nargs="+", default=[1, 2])
    r.add_argument("--steps", type=int, default=10)
    r.add_argument("--buffer", type=int, default=4)
    a = ap.parse_args()
    if a.cmd == "write":
        write(a.out, a.identities, a.views)
    elif a.cmd == "tools":
        tools(a.dataset)
    elif a.cmd == "measure":
        measure(a.dataset, a.buffer, a.ranks, a.steps, a.workers, a.views_per_load)
    elif a.cmd == "train-rss":
        train_rss(a.dataset, a.ranks, a.steps, a.buffer)
    else:
        webdataset_pipeline(a.dataset, a.workers, a.frames)


if __name__ == "__main__":
    main()
