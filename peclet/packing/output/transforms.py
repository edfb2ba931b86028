"""The bed's poses as a CSV: :func:`write_transforms_csv` and :func:`read_transforms_csv`
(world frame, quaternions (x, y, z, w) home -> world, floats that read back bit for bit)."""
from __future__ import annotations

import csv

import numpy as np

from peclet.core.files import atomic_write, check_writable_path
from peclet.core.validation import PecletArgumentError

from .meshing import check_pack

__all__ = ["write_transforms_csv", "read_transforms_csv", "CSV_HEADER"]

CSV_HEADER = ("id", "element", "x", "y", "z", "qx", "qy", "qz", "qw")


def write_transforms_csv(path, pack, element="element"):
    """Write ``id, element, x, y, z, qx, qy, qz, qw`` per element (world frame, quaternion
    (x, y, z, w) home -> world), floats as ``repr`` so they read back bit for bit."""
    pack = check_pack(pack)
    path = check_writable_path(path, "path")
    if not isinstance(element, str) or not element or "," in element or "\n" in element:
        raise PecletArgumentError("element", "a non-empty name without commas or newlines",
                                  element)

    def write(tmp):
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_HEADER)
            for i, (p, q) in enumerate(zip(pack.positions, pack.quaternions)):
                w.writerow([i, element] + [repr(float(v)) for v in (*p, *q)])

    return atomic_write(path, write)


def read_transforms_csv(path):
    """Read a transforms CSV: dict(ids (N,), element (list of str), positions (N, 3),
    quaternions (N, 4))."""
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    if not rows or tuple(rows[0]) != CSV_HEADER:
        raise ValueError(f"{path}: not a transforms CSV (header {','.join(CSV_HEADER)})")
    body = rows[1:]
    num = np.array([[float(v) for v in r[2:9]] for r in body], dtype=np.float64).reshape(-1, 7)
    return dict(ids=np.array([int(r[0]) for r in body], np.int64),
                element=[r[1] for r in body], positions=num[:, :3], quaternions=num[:, 3:])
