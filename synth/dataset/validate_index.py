"""``synth validate``'s checks of the signatures (``index.json`` and the commit records,
:mod:`synth.dataset.index`), and ``synth validate --repair-index``, the explicit repair.

Both shard forms are signed alike: the signature of a directory shard is the sha256 of its
``manifest.json``, that of a tar shard the sha256 of its ``<id>.tar.json`` (which holds the
tar's own sha256), so a tar, a member or a manifest changed after the commit is caught the
same way, and only :func:`repair` signs them again.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from synth.dataset.defects import Defect, Report
from synth.dataset.index import REPAIR_HINT, IndexDamaged, dataset_digest, read_index, read_records, repair_index
from synth.dataset.layout import LOGS_DIR, MANIFEST_FILE, STAGING_DIR, entry_kind, utc_now
from synth.dataset.shards import load_dataset
from synth.dataset.tarshard import committed_forms

#: Where ``synth validate --repair-index`` appends what each repair changed (JSON lines).
REPAIR_LOG = "index-repairs.jsonl"


def check_signatures(root: Path, rep: Report, plan_hash: str, present: list[str]) -> dict[str, dict]:
    """Report what is wrong with ``index.json`` and the commit records, given the shards
    ``present`` under ``shards/`` (either form); returns every shard's signature (its commit
    record, else its index entry) to check the manifests against."""
    try:
        idx = read_index(root)
    except IndexDamaged as e:
        rep.defects.append(Defect(None, None, "index", f"index.json is damaged ({e}); {REPAIR_HINT}"))
        idx = None
    else:
        if idx is None and present:
            rep.defects.append(Defect(None, None, "index", "index.json is missing (a render that resumes rewrites it "
                                                           f"from the commit records; or {REPAIR_HINT})"))
        elif idx is not None and idx["plan_hash"] != plan_hash:
            rep.defects.append(Defect(None, None, "index", f"index.json belongs to another plan; {REPAIR_HINT}"))
            idx = None
    entries = (idx or {}).get("shards", {})
    if idx is not None:
        rep.digest = idx.get("digest")
        if rep.digest is None:
            rep.warnings.append(Defect(None, None, "index", "index.json has no digest (written by an older synth); "
                                                            "--repair-index adds one"))
        elif rep.digest != dataset_digest(entries):
            rep.defects.append(Defect(None, None, "index", "index.json's digest does not match its entries (edited?)"))
    records, problems = read_records(root, plan_hash)
    for msg in problems:
        rep.defects.append(Defect(None, None, "index", msg))
    for s in sorted(set(records) & set(present)):
        if idx is not None and entries.get(s) != records[s]:
            rep.warnings.append(Defect(s, None, "index", "index.json is behind the shard's commit record (the next "
                                                         "render rewrites it)"))
    for s in sorted(set(entries) - set(present)):
        if entry_kind(root / STAGING_DIR / s / MANIFEST_FILE) == "file":
            rep.warnings.append(Defect(s, None, "index", "commit in progress or interrupted (the next render "
                                                         "finishes it)"))
        elif not committed_forms(root, s):
            rep.defects.append(Defect(s, None, "index", "index.json lists a shard that is not on disk"))
    return {**entries, **records}


def repair(root) -> list[dict]:
    """``synth validate --repair-index``: rebuild ``index.json`` and the commit records from
    the manifests of both shard forms (signing what they now say), append the changes to
    ``DIR/logs/index-repairs.jsonl`` and return them."""
    ds = load_dataset(root)
    _, changes = repair_index(ds.root, ds.plan_hash)
    if changes:
        log = ds.root / LOGS_DIR
        log.mkdir(exist_ok=True)
        with open(log / REPAIR_LOG, "a", encoding="utf-8") as f:
            f.write(json.dumps({"time": utc_now(), "pid": os.getpid(), "changes": changes}) + "\n")
    return changes


def describe_change(c: dict) -> str:
    """One line for a change made by :func:`repair`."""
    what = c["shard"] or "index.json"
    detail = c.get("reason") or ""
    if "old" in c or "new" in c:
        detail = f"manifest sha256 {c.get('old', '-')[:16]} -> {c.get('new', '-')[:16]}"
    return f"{what}: {c['change']}" + (f" ({detail})" if detail else "")
