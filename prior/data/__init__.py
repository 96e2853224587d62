"""Frames -> rays, codes and bounds for training the prior (see docs/prior.md)."""

from prior.data.bounds import bounding_sphere, foreground_points, intersect_sphere
from prior.data.codes import CodeLayout
from prior.data.sampler import Batch, RaySampler, pixel_radius, rays_for
from prior.data.store import FrameStore, IdentityInfo, load_store

__all__ = ["Batch", "CodeLayout", "FrameStore", "IdentityInfo", "RaySampler", "bounding_sphere", "foreground_points",
           "intersect_sphere", "load_store", "pixel_radius", "rays_for"]
