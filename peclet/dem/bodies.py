"""Per-particle state: the N bodies' arrays and their validated setters.

Frames: ``pos`` centres of mass (world), ``quat`` (x, y, z, w) unit, active, home -> world,
``vel``/``omega`` world frame (omega in rad / time), ``inv_mass`` (0 = not moved by contacts or
gravity), ``inv_inertia`` the principal inverse moments 1 / (mass length^2) (0 = a locked axis;
a NaN row = the default, a uniform solid sphere of the shape's bounding radius).

Extreme finite numbers (:mod:`peclet.dem.limits`): coordinates of magnitude <= 1e100, speeds
and angular speeds <= 1e100, inverse masses and moments 0 or in [1e-100, 1e100].
"""
from __future__ import annotations

import numpy as np

from peclet.core.geom.transforms import normalize_rows, quats_to_matrices
from peclet.core.validation import PecletArgumentError, check_array
from peclet.dem.limits import check_inverses, check_magnitudes, check_row_norms

_IDENTITY = np.array([0.0, 0.0, 0.0, 1.0])

#: (attribute, default of a new particle)
FIELDS = (("pos", 0.0), ("vel", 0.0), ("omega", 0.0), ("quat", _IDENTITY), ("shape", 0),
          ("inv_mass", 1.0), ("inv_inertia", np.nan))


class Bodies:
    """The arrays of N bodies. Setters validate (PecletArgumentError naming the argument); a
    setter called while N == 0 defines N, otherwise its row count must be N."""

    def __init__(self):
        self.n = 0
        self.pos = np.zeros((0, 3))
        self.vel = np.zeros((0, 3))
        self.omega = np.zeros((0, 3))
        self.quat = np.zeros((0, 4))
        self.shape = np.zeros(0, np.int64)
        self.inv_mass = np.zeros(0)
        self.inv_inertia = np.zeros((0, 3))

    def resize(self, n):
        """Keep the first min(N, n) bodies' attributes, default the rest. True if N changed."""
        if n == self.n:
            return False
        k = min(self.n, n)
        for name, fill in FIELDS:
            a = getattr(self, name)
            out = np.empty((n,) + a.shape[1:], a.dtype)
            out[:k] = a[:k]
            out[k:] = fill
            setattr(self, name, out)
        self.n = n
        return True

    def _rows(self, name, value, tail, nonneg=False):
        # a validated float64 copy with N rows; defines N while N == 0
        a = check_array(name, value, (None,) + tail)
        if nonneg and np.any(a < 0.0):
            raise PecletArgumentError(name, "an array with every entry >= 0", value)
        if self.n == 0 and len(a) > 0:
            self.resize(len(a))
        elif len(a) != self.n:
            raise PecletArgumentError(name, f"an array with N = {self.n} rows", value,
                                      f"{len(a)} rows")
        return a.copy()

    def set_positions(self, positions):
        p = check_array("positions", positions, (None, 3))
        check_magnitudes("positions", p, positions, "coordinates")
        self.resize(len(p))
        self.pos = p.copy()

    def set_shape_ids(self, ids, n_shapes):
        try:
            a = np.asarray(ids)
        except (TypeError, ValueError):
            a = np.zeros((0, 0))                        # ragged: refused below
        integral = (a.dtype.kind in "iu" or (a.dtype.kind == "f" and np.all(np.isfinite(a))
                                             and np.all(a == np.round(a))))
        if a.ndim != 1 or not integral:
            raise PecletArgumentError("ids", "a 1-D array of integers (shape ids)", ids)
        a = a.astype(np.int64)
        if len(a) and (a.min() < 0 or a.max() >= n_shapes):
            raise PecletArgumentError("ids", f"registered shape ids in [0, {n_shapes})", ids,
                                      f"values in [{a.min()}, {a.max()}]")
        self.shape = self._rows("ids", a, (), False).astype(np.int64)

    def set_quaternions(self, quats):
        q = self._rows("quats", quats, (4,))
        unit, bad = normalize_rows(q)
        if bad >= 0:
            raise PecletArgumentError("quats", "rows that are non-zero quaternions (x, y, z, w)",
                                      quats, f"row {bad} is zero")
        self.quat = unit

    def set_inv_mass(self, inv_mass):
        a = self._rows("inv_mass", inv_mass, (), nonneg=True)
        check_inverses("inv_mass", a, inv_mass)
        self.inv_mass = a

    def set_inv_inertia(self, inv_inertia):
        a = self._rows("inv_inertia", inv_inertia, (3,), nonneg=True)
        check_inverses("inv_inertia", a, inv_inertia)
        self.inv_inertia = a

    def set_velocities(self, v):
        a = self._rows("velocities", v, (3,))
        check_row_norms("velocities", a, v)
        self.vel = a

    def set_angular_velocities(self, w):
        a = self._rows("angular_velocities", w, (3,))
        check_row_norms("angular_velocities", a, w, unit="rad/time")
        self.omega = a

    def resolved_inv_inertia(self, radii):
        """Inverse moments with the NaN (default) rows resolved: a uniform solid sphere of the
        bounding radius, 1 / I = 2.5 inv_mass / r^2. ``radii`` (N,) the bodies' radii."""
        ii = self.inv_inertia.copy()
        bad = np.isnan(ii[:, 0]) if len(ii) else np.zeros(0, bool)
        if np.any(bad):
            r = radii[bad]
            ii[bad] = (self.inv_mass[bad] * 2.5 / r ** 2)[:, None]
        return ii

    def kinetic_energy(self, inv_inertia):
        """Translational plus rotational kinetic energy with the resolved principal inverse
        moments ``inv_inertia`` (N, 3); bodies with inverse mass 0 contribute no translational
        part, locked axes no rotational part."""
        m = self.inv_mass > 0
        et = 0.5 * float(((self.vel[m] ** 2).sum(axis=1) / self.inv_mass[m]).sum())
        if self.n == 0:
            return et
        wb = np.einsum("nji,nj->ni", quats_to_matrices(self.quat), self.omega)
        with np.errstate(divide="ignore", invalid="ignore"):
            er = np.where(inv_inertia > 0, wb ** 2 / inv_inertia, 0.0)
        return et + 0.5 * float(er.sum())
