"""``synth report DIR``: a dataset at a glance, as one self-contained HTML page or JSON.

- :mod:`synth.report.collect`: what is read (committed frames' JSON, plan, progress);
- :mod:`synth.report.logs`: render times, failures and retries from the render logs;
- :mod:`synth.report.plots`: the matplotlib figures (Agg backend), as PNG bytes;
- :mod:`synth.report.html`: the page (PNGs embedded as data URIs: one file, no scripts).
"""
