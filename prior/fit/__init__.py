"""Few-shot reconstruction, the parts that do not need the NeRF prior: the head model in
torch, landmark sources, head-model and camera fitting to 2D landmarks, and expression
interpolation for novel views (docs/fitting.md)."""
