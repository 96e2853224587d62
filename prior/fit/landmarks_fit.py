"""Head model and camera fitting to probabilistic 2D landmarks (paper Sec. 3.3, supp. "3DMM Fitting").

Minimises, in torch (float64, CPU by default),

    E = sum_{j,k} |x_jk - mu_jk|^2 / (2 sigma_jk^2)        landmarks, image j, point k
      + w_id  * -log p_GMM(beta)                           identity (the planner's mixture)
      + w_ex  * mean_i |psi_i|^2                           expression codes
      + w_jt  * mean_i |r_i|^2                             joint rotations (jaw, eyes)
      + w_mc  * sum_i (|psi_i - mean psi|^2 + |r_i - mean r|^2)   micro-changes (per-image mode)

over the identity code beta (shared), the expression code and joint rotations (one shared
set, or one per image, kept close to their mean: small involuntary changes between photos
taken one after another), the cameras' extrinsics (one per image) and, when
the intrinsics are unknown, one shared focal length. No self-intersection term (not
implemented). A stiff penalty (zero unless a landmark comes within 1 cm of a camera plane)
keeps the landmarks in front of every camera.

Gauge. Moving the head and every camera by one rigid motion changes no pixel, so with free
extrinsics the head is held at rest (root joint rotation 0, translation 0: the model frame,
the frame synth renders and the NeRF prior use) and only cameras move. With known
extrinsics (``Observations.world_to_camera``) the cameras are held and the head's rigid
placement (root rotation and translation, not regularised) is fitted instead.

Joints. The paper regularises the neck and eyeball joints but not the global head joint.
In synth's models the root joint ``neck`` carries the whole head (the global rigid joint,
fixed by the gauge), ``head`` is the neck-to-head articulation: every landmark is on the
head, so it is a second gauge direction (a head rotation and the opposite camera motion
give the same pixels) and is not fitted by default; the fitted, L2-regularised joints are
``jaw``, ``eye_l`` and ``eye_r`` (any joint can be listed in ``FitOptions.joints``).

Stages: (0) a closed-form weak-perspective pose per image from the mean face
(:func:`prior.fit.camera.weak_perspective_pose`); (1) cameras (and focal) alone on the mean
face; (2) everything together. Both by Levenberg-Marquardt (:mod:`prior.fit.lm`) until an
accepted step lowers E by less than ``rel_tol`` relatively.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch

from prior.fit.camera import project, weak_perspective_pose
from prior.fit.head import TorchHeadModel
from prior.fit.identity_prior import TorchGMM
from prior.fit.lm import levenberg_marquardt
from prior.fit.rotations import axis_angle_to_matrix
from synth.errors import SynthError
from synth.model.format import HeadModelData

#: Fewest visible landmarks per image for a camera estimate.
MIN_LANDMARKS = 6


@dataclass
class Observations:
    """Probabilistic landmarks of N images: means (N, L, 2) in pixels (synth's convention,
    top-left corner at 0) and sigmas (N, L) in pixels; a non-finite sigma marks a point as
    unused. ``K`` (N, 3, 3) known intrinsics, else None (then ``width``/``height`` are needed
    and a shared focal length is fitted). ``world_to_camera`` (N, 4, 4) known extrinsics or None.
    The points are the model's landmark set ``landmark_set``, or surface points given as
    ``landmark_def`` (triangle indices (L,), barycentric weights (L, 3)) under that name.
    ``focal_init`` (N,) pixels: each image's initial focal length when K is unknown (e.g. from
    EXIF; one shared factor is fitted), else None (from ``FitOptions.focal_init_fov_deg``)."""

    mean: np.ndarray
    sigma: np.ndarray
    width: np.ndarray
    height: np.ndarray
    K: np.ndarray | None = None
    world_to_camera: np.ndarray | None = None
    landmark_set: str = "ibug68"
    landmark_def: tuple[np.ndarray, np.ndarray] | None = None  # (triangles, bary) if not a set of the model
    focal_init: np.ndarray | None = None

    def __post_init__(self):
        self.mean = np.asarray(self.mean, np.float64)
        self.sigma = np.asarray(self.sigma, np.float64)
        N = self.mean.shape[0]
        self.width = np.broadcast_to(np.asarray(self.width, np.int64), (N,)).copy()
        self.height = np.broadcast_to(np.asarray(self.height, np.int64), (N,)).copy()
        if self.mean.ndim != 3 or self.mean.shape[2] != 2 or self.sigma.shape != self.mean.shape[:2]:
            raise SynthError(f"landmarks must be (N, L, 2) with sigmas (N, L), got {self.mean.shape} and "
                             f"{self.sigma.shape}", "landmarks", "pass one row of points per image")
        if self.K is not None:
            self.K = np.broadcast_to(np.asarray(self.K, np.float64), (N, 3, 3)).copy()
        if self.world_to_camera is not None:
            self.world_to_camera = np.asarray(self.world_to_camera, np.float64).reshape(N, 4, 4)
        if self.focal_init is not None:
            self.focal_init = np.broadcast_to(np.asarray(self.focal_init, np.float64), (N,)).copy()
            if not np.all(np.isfinite(self.focal_init) & (self.focal_init > 0)):
                raise SynthError(f"initial focal lengths {self.focal_init.tolist()} must be positive", "landmarks",
                                 "pass focal lengths in pixels, or none")

    @property
    def used(self) -> np.ndarray:
        return np.isfinite(self.sigma) & (self.sigma > 0) & np.all(np.isfinite(self.mean), -1)


@dataclass(frozen=True)
class FitOptions:
    per_image_expression: bool = False  # one code (and joint pose) per image, else one shared
    joints: tuple[str, ...] = ("jaw", "eye_l", "eye_r")
    w_landmarks: float = 1.0
    w_identity: float = 1.0
    w_expression: float = 1.0
    w_joints: float = 1.0
    w_micro: float = 100.0  # per-image deviations from the shared code (per-image mode)
    # box for every expression coefficient (per image): the planner's default
    # expression.code_range, so fits stay in the space the prior was trained on; None = unbounded
    expression_bounds: tuple[float, float] | None = (0.0, 1.0)
    focal_init_fov_deg: float = 50.0  # initial horizontal field of view when K is unknown
    # unknown focal length: log-normal prior around the initial one (sd in log units; 0.7 ~ a
    # factor of 2) and a hard range of horizontal fields of view. Without them a nearly
    # orthographic fit (f -> infinity) can win when perspective cues are weak (few landmarks)
    focal_prior_sd: float = 0.7
    fov_range_deg: tuple[float, float] = (3.0, 120.0)
    camera_iters: int = 50
    max_iters: int = 300
    rel_tol: float = 1e-10


@dataclass
class FitResult:
    identity: np.ndarray  # (Ki,)
    expression: np.ndarray  # (N, Ke), one row per image (equal rows when shared)
    joint_rotations: np.ndarray  # (N, J, 3) axis-angle, all joints of the model
    head_to_world: np.ndarray  # (4, 4): the identity with free cameras (gauge)
    K: np.ndarray  # (N, 3, 3)
    world_to_camera: np.ndarray  # (N, 4, 4)
    energy: dict[str, float]  # terms at the optimum, and "total"
    landmarks_2d: np.ndarray  # (N, L, 2) projections of the fitted model
    rmse_px: np.ndarray  # (N,) root mean square distance to the used observed points
    converged: bool  # the final stage met its tolerance (the camera stage is a capped warm start)
    iterations: dict[str, int]
    grad_norm: float
    history: list[float] = field(default_factory=list)  # E after each accepted step of the last stage

    def to_json(self) -> dict:
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in asdict(self).items()}


class _Problem:
    """Named parameter blocks, the residual vector and the identity term of one fit."""

    def __init__(self, model: HeadModelData, obs: Observations, opt: FitOptions, head: TorchHeadModel | None,
                 gmm: TorchGMM | None, start: tuple | None = None):
        dt = self.dt = torch.float64
        self.head = head or TorchHeadModel(model, dt)
        if obs.landmark_def is not None:
            self.head.define_landmarks(obs.landmark_set, *obs.landmark_def)
        self.gmm = gmm or TorchGMM.from_model(model, dt)
        self.obs, self.opt = obs, opt
        N = self.N = obs.mean.shape[0]
        self.E = N if opt.per_image_expression else 1  # rows of expression codes and joint poses
        for j in opt.joints:
            if j not in self.head.joint_index:
                raise SynthError(f"unknown joint '{j}'", "fit options", f"joints are {self.head.joint_names}")
        self.jidx = torch.tensor([self.head.joint_index[j] for j in opt.joints], dtype=torch.long)
        self.root = self.head.parents.index(-1)
        used = obs.used
        n_used = used.sum(1)
        if np.any(n_used < MIN_LANDMARKS):
            i = int(np.argmin(n_used))
            raise SynthError(f"image {i} has {int(n_used[i])} usable landmarks, the fit needs at least "
                             f"{MIN_LANDMARKS}", "landmarks", "use views where the face is visible")
        t = lambda a: torch.as_tensor(np.asarray(a, np.float64), dtype=dt)  # noqa: E731
        self.mu = t(np.where(used[..., None], obs.mean, 0.0))
        self.w_px = t(np.where(used, np.sqrt(opt.w_landmarks) / np.where(used, obs.sigma, 1.0), 0.0))[..., None]
        if obs.K is not None:
            self.K0 = t(obs.K)
        else:
            W, H = obs.width.astype(np.float64), obs.height.astype(np.float64)
            K0 = np.zeros((N, 3, 3))
            K0[:, 0, 0] = K0[:, 1, 1] = 0.5 * W / np.tan(0.5 * np.deg2rad(opt.focal_init_fov_deg)) \
                if obs.focal_init is None else obs.focal_init
            K0[:, 0, 2], K0[:, 1, 2], K0[:, 2, 2] = 0.5 * W, 0.5 * H, 1.0
            self.K0 = t(K0)
        nj, Ke = len(opt.joints), self.head.Ke
        self.values: dict[str, torch.Tensor] = {
            "omega": torch.zeros(N, 3, dtype=dt), "tcam": torch.zeros(N, 3, dtype=dt),
            "log_f": torch.zeros(1, dtype=dt), "root_rot": torch.zeros(3, dtype=dt),
            "trans": torch.zeros(3, dtype=dt), "beta": self.gmm.mean().clone(),
            "psi": torch.zeros(self.E, Ke, dtype=dt), "jrot": torch.zeros(self.E, nj, 3, dtype=dt)}
        if start is not None:  # given codes instead of the mean face
            beta, psi, rot = start
            self.values["beta"] = t(beta).reshape(self.head.Ki)
            self.values["psi"] = t(psi).reshape(1, Ke).expand(self.E, -1).clone()
            if rot is not None:
                self.values["jrot"] = t(rot).reshape(self.head.J, 3)[self.jidx].expand(self.E, -1, -1).clone()
        known = obs.world_to_camera is not None
        self.camera_blocks = (["root_rot", "trans"] if known else ["omega", "tcam"]) + (
            [] if obs.K is not None else ["log_f"])
        if known:
            self.R0 = t(obs.world_to_camera[:, :3, :3])
            self.values["tcam"] = t(obs.world_to_camera[:, :3, 3])
        else:
            self.R0, self.values["tcam"] = self._initial_cameras()
        self.all_blocks = self.camera_blocks + ["beta", "psi", "jrot"]

    def _initial_cameras(self) -> tuple[torch.Tensor, torch.Tensor]:
        v = self.values
        with torch.no_grad():
            X = self.head.landmarks(v["beta"], v["psi"], self.joint_rotations(v, v["jrot"]),
                                    landmark_set=self.obs.landmark_set)[0].numpy()
        used = self.obs.used
        poses = [weak_perspective_pose(X[used[i]], self.obs.mean[i, used[i]], self.K0[i].numpy())
                 for i in range(self.N)]
        return (torch.as_tensor(np.stack([p[0] for p in poses]), dtype=self.dt),
                torch.as_tensor(np.stack([p[1] for p in poses]), dtype=self.dt))

    # ---- packing ------------------------------------------------------------------------

    def pack(self, names: list[str]) -> torch.Tensor:
        return torch.cat([self.values[n].reshape(-1) for n in names])

    def unpack(self, theta: torch.Tensor, names: list[str]) -> dict[str, torch.Tensor]:
        v, i = dict(self.values), 0
        for n in names:
            k = self.values[n].numel()
            v[n] = theta[i:i + k].reshape(self.values[n].shape)
            i += k
        return v

    def recentre(self, theta: torch.Tensor, names: list[str]) -> torch.Tensor:
        """Store theta; fold the camera rotation increments into R0 (keeps them small)."""
        v = self.unpack(theta.detach(), names)
        self.R0 = axis_angle_to_matrix(v["omega"]) @ self.R0
        v["omega"] = torch.zeros_like(v["omega"])
        self.values = {k: x.clone() for k, x in v.items()}
        return self.pack(names)

    # ---- model ---------------------------------------------------------------------------

    @staticmethod
    def codes(v) -> tuple[torch.Tensor, torch.Tensor]:
        """Expression codes (E, Ke) and fitted joint rotations (E, nj, 3): E = 1 when shared
        (the head is then evaluated once for all images), else one row per image."""
        return v["psi"], v["jrot"]

    def joint_rotations(self, v, jrot: torch.Tensor) -> torch.Tensor:
        """All joints' rotations (E, J, 3) from the fitted ones (and the root's, when fitted)."""
        E = jrot.shape[0]
        rot = torch.zeros(E, self.head.J, 3, dtype=self.dt).index_copy(1, self.jidx, jrot)
        if "root_rot" in self.camera_blocks:
            rot = rot.index_copy(1, torch.tensor([self.root]), v["root_rot"].expand(E, 1, 3))
        return rot

    def cameras(self, v) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        R = axis_angle_to_matrix(v["omega"]) @ self.R0
        # the focal length (and skew) scale with s = exp(log_f), the principal point stays; the
        # cameras' depth translation scales with s too ("dolly zoom"), so changing the focal
        # length alone keeps the head's image size and only changes the perspective: this
        # turns the long curved focal-distance valley into a straight one
        s = torch.exp(v["log_f"][0])
        mask = torch.tensor([[1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [0.0, 0.0, 0.0]], dtype=self.dt)
        t = v["tcam"] * torch.stack([torch.ones_like(s), torch.ones_like(s), s])
        return R, t, self.K0 * (1.0 + (s - 1.0) * mask)

    def project(self, v) -> tuple[torch.Tensor, torch.Tensor]:
        psi, jrot = self.codes(v)
        X = self.head.landmarks(v["beta"], psi, self.joint_rotations(v, jrot), v["trans"],
                                landmark_set=self.obs.landmark_set).expand(self.N, -1, -1)
        R, tcam, K = self.cameras(v)
        return project(X, R, tcam, K)

    def residual_parts(self, v) -> dict[str, torch.Tensor]:
        uv, z = self.project(v)
        psi, jrot = self.codes(v)
        rows = 1.0 / psi.shape[0]  # mean over images of |psi_i|^2 and |r_i|^2
        parts = {
            "landmarks": ((uv - self.mu) * self.w_px).reshape(-1),
            "expression": np.sqrt(2.0 * self.opt.w_expression * rows) * psi.reshape(-1),
            "joints": np.sqrt(2.0 * self.opt.w_joints * rows) * jrot.reshape(-1),
            "behind": np.sqrt(2e6) * torch.relu(0.01 - z).reshape(-1),
        }
        if "log_f" in self.camera_blocks:
            parts["focal"] = v["log_f"] / self.opt.focal_prior_sd
        if self.opt.per_image_expression:  # deviations from the images' mean code and pose
            parts["micro"] = np.sqrt(2.0 * self.opt.w_micro) * torch.cat([(psi - psi.mean(0)).reshape(-1),
                                                                          (jrot - jrot.mean(0)).reshape(-1)])
        return parts

    def identity_term(self, v) -> torch.Tensor:
        return self.opt.w_identity * self.gmm.nll(v["beta"])

    def bounds(self, names: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Boxes: every expression coefficient (of every image) within ``expression_bounds``;
        the focal length within ``fov_range_deg``."""
        lo = {n: torch.full_like(self.values[n], -float("inf")) for n in names}
        hi = {n: torch.full_like(self.values[n], float("inf")) for n in names}
        if "log_f" in names:  # the field-of-view range as bounds on log(f / f0)
            f0 = float(self.K0[0, 0, 0])
            W = float(self.obs.width[0])
            for bound, fov in ((hi, self.opt.fov_range_deg[0]), (lo, self.opt.fov_range_deg[1])):
                bound["log_f"].fill_(float(np.log(0.5 * W / np.tan(0.5 * np.deg2rad(fov)) / f0)))
        if self.opt.expression_bounds is not None:
            a, b = self.opt.expression_bounds
            if "psi" in names:
                lo["psi"].fill_(a)
                hi["psi"].fill_(b)
        return torch.cat([lo[n].reshape(-1) for n in names]), torch.cat([hi[n].reshape(-1) for n in names])

    def lid_block(self, names: list[str]) -> torch.Tensor:
        """Indices into theta of the parameters the eyelid rig bends the landmarks with
        (TorchHeadModel.eyelid_parameters: eye-region codes, fitted eye joints), for the
        solver's exact curvature block (prior.fit.lm); empty without a rig."""
        codes, joints = self.head.eyelid_parameters()
        fitted = [k for k, j in enumerate(self.jidx.tolist()) if j in joints]
        out, i = [], 0
        for n in names:
            if n == "psi":
                out += [i + row * self.head.Ke + c for row in range(self.E) for c in codes]
            elif n == "jrot":
                out += [i + (row * len(self.jidx) + k) * 3 + a for row in range(self.E) for k in fitted for a in range(3)]
            i += self.values[n].numel()
        return torch.tensor(out, dtype=torch.long)

    def solve(self, names: list[str], max_iters: int):
        beta_at = None
        if "beta" in names:
            i = 0
            for n in names:
                if n == "beta":
                    beta_at = slice(i, i + self.values[n].numel())
                i += self.values[n].numel()

        def curvature(theta):
            H = torch.zeros(theta.numel(), theta.numel(), dtype=self.dt)
            if beta_at is not None:
                H[beta_at, beta_at] = self.opt.w_identity * self.gmm.curvature(theta[beta_at])
            return H

        lower, upper = self.bounds(names)
        theta, rep = levenberg_marquardt(
            lambda th: torch.cat(list(self.residual_parts(self.unpack(th, names)).values())),
            lambda th: self.identity_term(self.unpack(th, names)), curvature, self.pack(names),
            lower=lower, upper=upper, accept=lambda th: self.recentre(th, names) if "omega" in names else th,
            max_iters=max_iters, rel_tol=self.opt.rel_tol, curved=self.lid_block(names))
        self.recentre(theta, names)
        return rep


def fit_landmarks(model: HeadModelData, obs: Observations, options: FitOptions | None = None, *,
                  head: TorchHeadModel | None = None, gmm: TorchGMM | None = None) -> FitResult:
    """Fit identity, expressions, joints and cameras (see the module docstring)."""
    opt = options or FitOptions()
    p = _Problem(model, obs, opt, head, gmm)
    rep1 = p.solve(p.camera_blocks, opt.camera_iters)
    rep2 = p.solve(p.all_blocks, opt.max_iters)
    return _result(p, {"cameras": rep1, "all": rep2})


def fit_cameras(model: HeadModelData, obs: Observations, identity, expression, joint_rotations=None,
                options: FitOptions | None = None, *, head: TorchHeadModel | None = None) -> FitResult:
    """Cameras (and focal length, when K is unknown) for a head with given codes: stages 0 and
    1 of :func:`fit_landmarks` with the given identity (Ki,), expression (Ke,) and joint
    rotations (J, 3) of ``options.joints`` (others ignored) instead of the mean face. With
    the true codes of a synthetic scene this measures what the landmarks' noise alone allows."""
    opt = options or FitOptions()
    p = _Problem(model, obs, opt, head, None, start=(identity, expression, joint_rotations))
    return _result(p, {"cameras": p.solve(p.camera_blocks, opt.max_iters)})


def _result(p: _Problem, reports: dict) -> FitResult:
    v, obs = p.values, p.obs
    with torch.no_grad():
        parts = p.residual_parts(v)
        uv, _ = p.project(v)
        R, tcam, K = p.cameras(v)
        psi, jrot = p.codes(v)
        rot = p.joint_rotations(v, jrot).expand(p.N, -1, -1)
        psi = psi.expand(p.N, -1)
        energy = {k: 0.5 * float((r * r).sum()) for k, r in parts.items()}
        energy["identity"] = float(p.identity_term(v))
    energy["total"] = float(sum(energy.values()))
    w2c = np.tile(np.eye(4), (p.N, 1, 1))
    w2c[:, :3, :3], w2c[:, :3, 3] = R.numpy(), tcam.numpy()
    head_to_world = np.eye(4)
    if "root_rot" in p.camera_blocks:  # the head's rigid placement: root rotation about its joint, then translation
        G = p.head.joint_transforms(v["beta"], rot[:1], v["trans"])[0].numpy()
        G0 = p.head.joint_transforms(v["beta"])[0].numpy()
        head_to_world = G[p.root] @ np.linalg.inv(G0[p.root])
    used = obs.used
    uvn = uv.numpy()
    d2 = np.where(used, ((uvn - obs.mean) ** 2).sum(-1), 0.0)
    rmse = np.sqrt(d2.sum(1) / np.maximum(used.sum(1), 1))
    last = list(reports.values())[-1]
    return FitResult(identity=v["beta"].numpy().copy(), expression=psi.numpy().copy(),
                     joint_rotations=rot.numpy().copy(), head_to_world=head_to_world, K=K.numpy().copy(),
                     world_to_camera=w2c, energy=energy, landmarks_2d=uvn, rmse_px=rmse,
                     converged=last.converged,  # the camera stage is a warm start, capped at camera_iters
                     iterations={k: r.iterations for k, r in reports.items()}, grad_norm=last.grad_norm,
                     history=last.history)
