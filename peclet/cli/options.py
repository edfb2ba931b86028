"""Options shared by the subcommands: the bed's (``pack``, ``ensemble``), and the number and
thread parsers of the kinematic-wall runs (``drum``, ``stir``)."""

from peclet.core.validation import PecletArgumentError

ELEMENT_HELP = (
    "library element (pall_ring, raschig_ring, berl_saddle, intalox_saddle, sphere, "
    "solid_cylinder), optionally with construction parameters NAME:KEY=V,KEY=V (e.g. "
    "pall_ring:thickness=0.024,n_windows=5; a triple as a/b/c), or a flat-encoding .npz "
    "(default pall_ring). Lengths are in the element's own unit, whose defaults make its "
    "diameter D = 1 (D = 2 r_outer, 2 radius or 2 R; containers are in D), so with the "
    "default size they read as fractions of D. Parameters [default]: "
    "pall_ring: r_outer > 0 [0.5]; height > 0 [1]; thickness in (0, r_outer), also <= "
    "window_half radial and <= 2 (r_outer - web_half x), i.e. (0, 0.16] at the other "
    "defaults [0.12]; n_windows integer in [1, 16] per row [4]; window_y in [0, height/2) "
    "[0.24]; window_half radial/axial/tangential, each > 0, radial >= thickness, axial < "
    "height/2 [0.16/0.17/0.13]; web_half x/y/z, each > 0, x <= r_outer - thickness/2 "
    "[0.4/0.06/0.06]. raschig_ring: r_outer > 0 [0.5]; height > 0 [1]; thickness in (0, "
    "r_outer) [0.12]. berl_saddle: R > 0, the torus centre-line radius [0.5]; r in (0, R), "
    "the tube radius [0.2]. intalox_saddle: R > 0 [0.5]; r in (0, R) [0.3]; thickness in "
    "(0, r) [0.06]. sphere: radius > 0 [0.5]. solid_cylinder: radius > 0 [0.5]; height > 0 "
    "[1]. Every length lies in [1e-6, 1e6] and within a factor 1000 of D. Out-of-range, "
    "unknown or non-numeric parameters are refused. Shell probes follow "
    "the thinnest wall (spacing <= its thickness): a thin-walled element gets more probes "
    "and packs slower (t/D = 0.02: about 15 000 probes, 2.5x the time per step).")
CONTAINER_HELP = ("box:L (periodic) | column:N (diameter N D, floor at y = 0) | walled:Lx,Lz, "
                  "in element diameters D, each in [1.5, 1e4] (default box:3.5, the page's)")


def add_bed_options(parser, protocols=("page", "rain")):
    """--element, --container and --protocol, with the page's defaults (values stay text: each
    command checks them before any work and names the flag in its one-line error).
    ``protocols``: the ones the command offers (the help lists them)."""
    parser.add_argument("--element", default="pall_ring", help=ELEMENT_HELP)
    parser.add_argument("--container", default="box:3.5", help=CONTAINER_HELP)
    extra = (" (grow: a periodic cube sized by --count without --container, or a closed "
             "box:AxBxC or column:N, in D, grown in by the same compression)"
             if "grow" in protocols else "")
    parser.add_argument("--protocol", default="page",
                        help=" | ".join(protocols) + " (default page)" + extra)


def number(flag, text, conv):
    """``text`` as a float, or (``conv`` int) an integer written as one (``"3"``, ``"3.0"``);
    otherwise a PecletArgumentError naming ``flag``."""
    try:
        if conv is int:
            v = float(text)
            if not v.is_integer():
                raise ValueError
            return int(v)
        return float(text)
    except (TypeError, ValueError, OverflowError):
        kind = "an integer" if conv is int else "a number"
        raise PecletArgumentError(flag, kind, text) from None


def threads_option(text, flag="--threads"):
    """The ``--threads`` value (None: numba's default), an integer in [1, NUMBA_NUM_THREADS]."""
    if text is None:
        return None
    import numba

    threads = number(flag, text, int)
    cap = int(numba.config.NUMBA_NUM_THREADS)
    if not 1 <= threads <= cap:
        raise PecletArgumentError(flag, f"in [1, {cap}] (NUMBA_NUM_THREADS)", threads)
    return threads
