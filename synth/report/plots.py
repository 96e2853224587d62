"""The report's figures, made with matplotlib's Agg backend and returned as PNG bytes.

Each function takes a :class:`synth.report.collect.Collected` and returns one PNG; a figure
whose data is empty (a dataset with nothing committed yet) says so instead of plotting.
"""

from __future__ import annotations

import io

import numpy as np

DPI = 80
#: ITA categories (degrees, dermatology scale): lower bound, name.
ITA_CATEGORIES = ((55, "very light"), (41, "light"), (28, "intermediate"), (10, "tan"), (-30, "brown"),
                  (-90, "dark"))


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI, bbox_inches="tight", metadata={"Software": None})
    _plt().close(fig)
    return buf.getvalue()


def _empty(ax, what: str) -> None:
    ax.text(0.5, 0.5, f"no {what} yet", ha="center", va="center", transform=ax.transAxes, color="0.4")
    ax.set_xticks([])
    ax.set_yticks([])


def _done(fig, titles: dict, empty: str | None = None) -> bytes:
    """Title the axes (axis -> title), mark them all empty when ``empty`` names what is missing,
    and return the PNG."""
    for ax, title in titles.items():
        if empty:
            _empty(ax, empty)
        ax.set_title(title)
    return _png(fig)


def _bins(n: int) -> int:
    return max(5, min(40, n // 3))


def _hist(ax, values, xlabel: str, ylabel: str, colour: str, missing: str, bins=None) -> bool:
    """A histogram of ``values`` with its axis labels, or a note that ``missing`` is not there yet;
    True when there was something to plot."""
    values = np.asarray(values)
    if not values.size:
        _empty(ax, missing)
        return False
    ax.hist(values, bins=_bins(values.size) if bins is None else bins, color=colour)
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    return True


def _bars(ax, labels, values, colour) -> None:
    """Vertical bars with the labels under them, turned."""
    x = np.arange(len(labels))
    ax.bar(x, values, color=colour)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=90, fontsize=6)


def _barh(ax, labels, values, colours, fontsize: int = 7) -> None:
    """Horizontal bars, first label on top."""
    y = np.arange(len(labels))
    ax.barh(y, values, color=colours)
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=fontsize)
    ax.invert_yaxis()


def identity_codes(c) -> bytes:
    fig, (a, b) = _plt().subplots(1, 2, figsize=(9, 3.4))
    X = c.identity_codes
    titles = {a: "identity code norms", b: "first two identity components"}
    if not len(X):
        return _done(fig, titles, "identities")
    a.hist(np.linalg.norm(X, axis=1), bins=_bins(len(X)), color="#4878a8")
    a.set_xlabel("|identity code| (model code units)")
    a.set_ylabel("identities")
    if X.shape[1] >= 2:
        b.scatter(X[:, 0], X[:, 1], s=10, alpha=0.6, color="#4878a8")
        b.set_xlabel("component 1")
        b.set_ylabel("component 2")
        b.set_aspect("equal", adjustable="datalim")
    else:
        _empty(b, "second component")
    return _done(fig, titles)


def expressions(c) -> bytes:
    fig, (a, b) = _plt().subplots(1, 2, figsize=(12, 3.6), gridspec_kw={"width_ratios": [3, 1.3]})
    E = c.expression_codes
    titles = {a: "expression components: how often active", b: "kinds and presets"}
    if not len(E):
        return _done(fig, titles, "expressions")
    rate = (np.abs(E) > 1e-6).mean(axis=0)
    _bars(a, c.expression_names, rate, "#6a9f58")
    a.set_ylabel("fraction of expressions")
    kinds, presets = sorted(c.expression_kinds), sorted(c.expression_presets)
    _barh(b, [f"kind: {k}" for k in kinds] + presets,
          [c.expression_kinds[k] for k in kinds] + [c.expression_presets[k] for k in presets],
          ["#888888"] * len(kinds) + ["#6a9f58"] * len(presets))
    b.set_xlabel("expressions")
    return _done(fig, titles)


def cameras(c) -> bytes:
    fig = _plt().figure(figsize=(11, 3.8))
    a = fig.add_subplot(1, 2, 1, projection="mollweide")
    b = fig.add_subplot(1, 2, 2)
    if c.azimuth_deg.size:
        a.scatter(np.radians(c.azimuth_deg), np.radians(c.elevation_deg), s=4, alpha=0.5, color="#b05a3c")
        a.grid(True, alpha=0.4)
        a.tick_params(labelsize=6)
    else:
        _empty(a, "views")
    ang = c.smallest_angle_deg[np.isfinite(c.smallest_angle_deg)]
    if _hist(b, ang, "smallest angle between two views of an expression (deg)", "expressions", "#b05a3c",
             "expressions with two views") and c.min_separation_deg is not None:
        b.axvline(c.min_separation_deg, color="k", ls="--", lw=1, label=f"minimum {c.min_separation_deg:g} deg")
        b.legend(fontsize=8)
    return _done(fig, {a: "viewpoints (azimuth, elevation; 0 = frontal)", b: "view separation"})


def assets(c) -> bytes:
    plt = _plt()
    classes = list(c.assets)
    ncol = 5
    nrow = -(-len(classes) // ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(14, 2.6 * nrow))
    axes = np.atleast_1d(axes).ravel()
    for ax, cls in zip(axes, classes):
        cnt = c.assets[cls]
        total = sum(cnt.values())
        if not total:
            _empty(ax, "identities")
        else:
            items = sorted(((str(k) if k is not None else "(none)"), v) for k, v in cnt.items())
            items.sort(key=lambda kv: -kv[1])
            items = items[:8]
            _barh(ax, [k for k, _ in items], [v for _, v in items],
                  ["#bbbbbb" if k == "(none)" else "#7a5aa8" for k, _ in items])
            ax.tick_params(axis="x", labelsize=7)
        present = sum(v for k, v in cnt.items() if k is not None)
        ax.set_title(f"{cls} ({present}/{total})", fontsize=9)
    for ax in axes[len(classes):]:
        ax.axis("off")
    fig.tight_layout()
    return _png(fig)


def skin_ita(c) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.2))
    if _hist(ax, c.ita_deg, "individual typology angle of the skin albedo (deg)", "identities", "#c08a60",
             "identities", bins=np.arange(-90, 91, 5)):
        for lo, name in ITA_CATEGORIES[:-1]:
            ax.axvline(lo, color="0.5", lw=0.6, ls=":")
            ax.text(lo + 1, ax.get_ylim()[1] * 0.92, name, fontsize=6, rotation=90, va="top", color="0.35")
    ax.set_title("skin tone (ITA)")
    return _png(fig)


def render_times(c) -> bytes:
    fig, (a, b) = _plt().subplots(1, 2, figsize=(10, 3.2))
    fs = np.array(list(c.render.get("frame_seconds", {}).values()))
    ss = c.render.get("shard_seconds", {})
    _hist(a, fs, "seconds in Cycles", "frames", "#4a9a9a", "render logs")
    if 0 < len(ss) <= 30:
        _bars(b, list(ss), np.array(list(ss.values())), "#4a9a9a")
        b.set_ylabel("seconds")
    else:
        _hist(b, list(ss.values()), "seconds per shard", "shards", "#4a9a9a", "render logs", bins=30)
    return _done(fig, {a: "render time per frame", b: "render time per shard"})


def failures(c) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(6, 2.6))
    r = c.render
    labels = ["runs", "attempts", "retried batches", "failed attempts", "error events"]
    vals = [r.get("runs", 0), r.get("attempts", 0), r.get("retried_batches", 0), r.get("failed_attempts", 0),
            len(r.get("errors", []))]
    _barh(ax, labels, vals, ["#888888", "#888888", "#d08c3c", "#c0392b", "#c0392b"], fontsize=9)
    for i, v in enumerate(vals):
        ax.text(v, i, f" {v}", va="center", fontsize=8)
    ax.set_title("render attempts, retries and failures")
    return _png(fig)


def progress(c) -> bytes:
    plt = _plt()
    p = c.progress
    fig, ax = plt.subplots(figsize=(7, 1.6))
    total = max(p["frames_planned"], 1)
    ax.barh([0], [p["frames_committed"] / total], color="#3c8d3c", label="committed")
    ax.barh([0], [p["frames_staged"] / total], left=[p["frames_committed"] / total], color="#d0b03c",
            label="staged (in progress)")
    ax.set_xlim(0, 1)
    ax.set_yticks([])
    ax.set_xlabel(f"fraction of {p['frames_planned']} planned frames")
    ax.legend(fontsize=7, loc="lower right")
    ax.set_title(f"{p['shards_committed']}/{p['shards_planned']} shards committed")
    return _png(fig)


#: (section title, figure function) in page order.
FIGURES = (("Progress", progress), ("Identities", identity_codes), ("Expressions", expressions),
           ("Cameras", cameras), ("Assets", assets), ("Skin", skin_ita), ("Render time", render_times),
           ("Failures and retries", failures))
