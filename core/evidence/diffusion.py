"""Edge-enhancing diffusion of the Lab a,b channels (seed eq. 11), AOS scheme.

The diffusivity g = 1 / (|grad u|^p + eps) is shared by all channels (|grad u|^2 sums the channels), so
colour regions flatten while their boundaries stay sharp. AOS (Weickert, ter Haar Romeny & Viergever
1998) splits the semi-implicit step into one tridiagonal system per row and per column:

    u^{k+1} = 1/2 sum_{l in x,y} (I - 2 tau A_l(u^k))^{-1} u^k

Every system is solved at once with a vectorised Thomas algorithm (loop only along the line length).
`diffusion_explicit_reference` integrates the same lagged-diffusivity equation with small explicit
steps; it is slow and only there to check the fast scheme.
"""
import numpy as np

from .errors import FeatureInputError


def _as_channels(u: np.ndarray) -> tuple[np.ndarray, bool]:
    """HxW or HxWxC float input -> HxWxC float64 copy, and whether a channel axis was added."""
    arr = np.asarray(u)
    if arr.ndim == 2:
        return arr[:, :, None].astype(np.float64), True
    if arr.ndim != 3:
        raise FeatureInputError(
            f"diffusion expects an HxW or HxWxC image, got shape {arr.shape}; pass the a,b channels as HxWx2")
    if arr.shape[0] < 2 or arr.shape[1] < 2:
        raise FeatureInputError(f"diffusion needs an image of at least 2x2 pixels, got {arr.shape[:2]}")
    return arr.astype(np.float64), False


def _check_params(steps, tau, eps, p):
    if steps < 0 or int(steps) != steps:
        raise FeatureInputError(f"steps must be a non-negative integer, got {steps!r}")
    if not tau > 0:
        raise FeatureInputError(f"tau (the time step) must be positive, got {tau!r}")
    if not eps > 0:
        raise FeatureInputError(f"eps must be positive (it bounds the diffusivity at 1/eps), got {eps!r}")
    if not p > 0:
        raise FeatureInputError(f"p must be positive, got {p!r}")


def joint_diffusivity(u: np.ndarray, eps: float, p: float) -> np.ndarray:
    """g = 1/(|grad u|^p + eps) per pixel (HxW) from central differences with mirrored borders."""
    grad_sq = np.zeros(u.shape[:2], dtype=u.dtype)
    for ch in range(u.shape[2]):
        band = u[:, :, ch]
        gy = np.empty_like(band)
        gy[1:-1] = 0.5 * (band[2:] - band[:-2])
        gy[0] = 0.5 * (band[1] - band[0])        # mirrored neighbour: u[-1] = u[0]
        gy[-1] = 0.5 * (band[-1] - band[-2])
        gx = np.empty_like(band)
        gx[:, 1:-1] = 0.5 * (band[:, 2:] - band[:, :-2])
        gx[:, 0] = 0.5 * (band[:, 1] - band[:, 0])
        gx[:, -1] = 0.5 * (band[:, -1] - band[:, -2])
        grad_sq += gx * gx + gy * gy
    return 1.0 / (np.power(grad_sq, 0.5 * p) + eps)


def thomas_solve(lower: np.ndarray, diag: np.ndarray, upper: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve many independent tridiagonal systems along axis 0 (shape N x K: K systems of length N).

    Row i reads lower[i] x[i-1] + diag[i] x[i] + upper[i] x[i+1] = rhs[i]; lower[0] and upper[N-1]
    are ignored. No pivoting: the AOS matrices are strictly diagonally dominant.
    """
    n = diag.shape[0]
    c_prime = np.empty_like(diag)
    x = np.empty_like(rhs)
    denom = diag[0].copy()
    c_prime[0] = upper[0] / denom
    x[0] = rhs[0] / denom
    for i in range(1, n):
        denom = diag[i] - lower[i] * c_prime[i - 1]
        c_prime[i] = upper[i] / denom
        x[i] = (rhs[i] - lower[i] * x[i - 1]) / denom
    for i in range(n - 2, -1, -1):
        x[i] -= c_prime[i] * x[i + 1]
    return x


def aos_step(u: np.ndarray, g: np.ndarray, tau: float) -> np.ndarray:
    """One AOS step for HxWxC u with a fixed HxW diffusivity g.

    All column systems (one per column and channel) and all row systems (one per row and channel) go
    into one batch of length max(H, W) so that the Python loop of the Thomas solver runs only once;
    the shorter systems are padded with identity rows, which are decoupled from the real ones.
    """
    h, w, c = u.shape
    length, k_cols, k_rows = max(h, w), w * c, h * c
    dtype = u.dtype
    step = 2.0 * tau
    # off[i + 1] couples line positions i and i + 1; off[0] and off[n] stay 0 (no flux across the border).
    off = np.zeros((length + 1, k_cols + k_rows), dtype=dtype)
    off[1:h, :k_cols] = np.repeat((-0.5 * step) * (g[:-1, :] + g[1:, :]), c, axis=1)
    off[1:w, k_cols:] = np.repeat((-0.5 * step) * (g[:, :-1] + g[:, 1:]).T, c, axis=1)
    diag = 1.0 - off[1:] - off[:-1]
    lines = np.zeros((length, k_cols + k_rows), dtype=dtype)
    lines[:h, :k_cols] = u.reshape(h, k_cols)
    lines[:w, k_cols:] = u.transpose(1, 0, 2).reshape(w, k_rows)
    # Solve for the change d = v - u: (I - 2 tau A) d = 2 tau A u. Same solution, but rounding errors
    # scale with the change instead of the values (a flat image stays exactly flat in float32).
    flux = off[1:length] * (lines[1:] - lines[:-1])      # -2 tau g_{i+1/2} (u_{i+1} - u_i)
    rhs = np.zeros_like(lines)
    rhs[:-1] -= flux
    rhs[1:] += flux
    change = thomas_solve(off[:-1], diag, off[1:], rhs)
    d_cols = change[:h, :k_cols].reshape(h, w, c)
    d_rows = change[:w, k_cols:].reshape(w, h, c).transpose(1, 0, 2)
    return u + 0.5 * (d_cols + d_rows)


def edge_enhancing_diffusion(ab: np.ndarray, steps: int = 5, tau: float = 2.0, eps: float = 1e-3,
                             p: float = 1.5) -> np.ndarray:
    """Jointly diffuse the channels of an HxWxC image (HxW also accepted); returns float32, same shape.

    Diffusion time is steps*tau; the diffusivity is recomputed from the current image every step.
    """
    _check_params(steps, tau, eps, p)
    u, squeeze = _as_channels(ab)
    u = u.astype(np.float32)   # float32 halves the memory traffic of the solver; the systems are well conditioned
    for _ in range(int(steps)):
        u = aos_step(u, joint_diffusivity(u, eps, p).astype(np.float32), tau)
    out = u.astype(np.float32)
    return out[:, :, 0] if squeeze else out


def _explicit_divergence(u: np.ndarray, g: np.ndarray) -> np.ndarray:
    """sum_l A_l u: flux differences between 4-neighbours, zero flux across the image border."""
    out = np.zeros_like(u)
    gy = 0.5 * (g[:-1, :] + g[1:, :])[:, :, None]
    flux_y = gy * (u[1:] - u[:-1])
    out[:-1] += flux_y
    out[1:] -= flux_y
    gx = 0.5 * (g[:, :-1] + g[:, 1:])[:, :, None]
    flux_x = gx * (u[:, 1:] - u[:, :-1])
    out[:, :-1] += flux_x
    out[:, 1:] -= flux_x
    return out


def diffusion_explicit_reference(ab: np.ndarray, steps: int = 5, tau: float = 2.0, eps: float = 1e-3,
                                 p: float = 1.5) -> np.ndarray:
    """Same model as `edge_enhancing_diffusion` (g frozen over each step of length tau), integrated with
    explicit Euler sub-steps small enough to be stable (dt * 4 max g <= 0.9). Slow; for tests only."""
    _check_params(steps, tau, eps, p)
    u, squeeze = _as_channels(ab)
    for _ in range(int(steps)):
        g = joint_diffusivity(u, eps, p)
        n_sub = int(np.ceil(tau * 4.0 * g.max() / 0.9))
        dt = tau / n_sub
        for _ in range(n_sub):
            u = u + dt * _explicit_divergence(u, g)
    out = u.astype(np.float32)
    return out[:, :, 0] if squeeze else out
