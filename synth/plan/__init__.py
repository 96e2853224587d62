"""The sampling plan: every random choice of a dataset, decided up front as plain data
(docs/plan-format.md).

``planner.run_plan`` samples and writes a plan directory (``synth plan``); ``io.load_plan``
reads one. Modules: ``identities``, ``expressions``, ``assets``, ``cameras`` (what is
sampled), ``planner`` (shard specs), ``io`` (writer, reader, schema), ``stats`` (summary),
``parallel`` (deterministic fork fan-out).
"""
