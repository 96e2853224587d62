"""Frames -> rays, codes and bounds for training the prior (see docs/prior.md):
sources (committed shards) -> prepare (identity table, code layout, bounds) -> stream (a bounded
buffer of decoded identities per rank) -> sampler (the paper's identities x views x pixels)."""

from prior.data.bounds import bounding_sphere, foreground_points, intersect_sphere
from prior.data.codes import CodeLayout
from prior.data.identities import IdentityInfo
from prior.data.prepare import Table, build_table, prepare
from prior.data.sampler import Batch, RaySampler, pixel_radius, rays_for
from prior.data.sources import Source, open_source
from prior.data.stream import IdentityData, Loader

__all__ = ["Batch", "CodeLayout", "IdentityData", "IdentityInfo", "Loader", "RaySampler", "Source", "Table",
           "bounding_sphere", "build_table", "foreground_points", "intersect_sphere", "open_source", "pixel_radius",
           "prepare", "rays_for"]
