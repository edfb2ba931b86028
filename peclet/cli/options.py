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


#: The Hertz law's options (given only with ``--contact hertz``): flag -> attribute.
HERTZ_OPTIONS = {"--youngs": "youngs", "--poisson": "poisson",
                 "--rayleigh-fraction": "rayleigh_fraction", "--density": "density",
                 "--diameter": "diameter"}


def add_contact_options(parser):
    """--contact and the Hertz law's --youngs, --poisson, --rayleigh-fraction, --density,
    --diameter (values stay text: :func:`contact_option` checks them)."""
    parser.add_argument("--contact", default="impulse", choices=("impulse", "hertz"),
                        help="contact law: impulse (the default, the page's engine) or hertz "
                        "(Hertz-Mindlin, explicit substeps; the model LAMMPS's hertz/material "
                        "+ mindlin runs)")
    parser.add_argument("--youngs", default=None,
                        help="hertz only: Young's modulus E. A number is in bed units (rho D "
                        "x 1 m/s^2, the bed's pressure unit: density 1, D = 1, g = 9.81); "
                        "with the suffix Pa (e.g. 1e7Pa) it is physical and converted with "
                        "--density and --diameter: E_bed = E / (density diameter x 1 m/s^2). "
                        "Default 1e7Pa (4e6 for 1 mm glass-like spheres)")
    parser.add_argument("--poisson", default=None,
                        help="hertz only: Poisson's ratio in (-1, 0.5) (default 0.3)")
    parser.add_argument("--rayleigh-fraction", default=None,
                        help="hertz only: the substep as a fraction of the element's Rayleigh "
                        "time, in (0, 0.3] (default 0.2); each protocol step (dt 2e-3) is "
                        "split into the fewest substeps that meet it (printed)")
    parser.add_argument("--density", default=None, help="hertz only, with --youngs ...Pa: "
                        "the elements' density in kg/m^3 (default 2500)")
    parser.add_argument("--diameter", default=None, help="hertz only, with --youngs ...Pa: "
                        "the element diameter D in m (default 1e-3)")


def contact_option(args, protocol=None):
    """The contact law of the command's ``--contact`` options: None (impulse) or a
    ``HertzContact``. A Hertz option without ``--contact hertz``, --density or --diameter
    without a physical --youngs (``...Pa``), ``--contact hertz`` with a protocol it does not
    run (``protocol`` "grow"), and every out-of-range value are one PecletArgumentError
    naming the flag."""
    from peclet.packing.bed.contact import DEFAULT_SI, HertzContact

    given = {f: getattr(args, a) for f, a in HERTZ_OPTIONS.items()
             if getattr(args, a) is not None}
    if args.contact != "hertz":
        for flag, value in given.items():
            raise PecletArgumentError(flag, "given only with --contact hertz", value)
        return None
    if protocol == "grow":
        raise PecletArgumentError("--contact", "impulse with --protocol grow (growth to "
                                  "jamming runs its own step)", args.contact)
    text = str(args.youngs if args.youngs is not None else f"{DEFAULT_SI['youngs']:g}Pa")
    si = text.strip().endswith("Pa")
    if not si:
        for flag in ("--density", "--diameter"):
            if flag in given:
                raise PecletArgumentError(flag, "given only with a physical --youngs (a value "
                                          "in Pa, e.g. 1e7Pa)", given[flag])
    kw = {}
    for flag, key in (("--poisson", "poisson"), ("--rayleigh-fraction", "rayleigh_fraction")):
        if flag in given:
            kw[key] = number(flag, given[flag], float)
    try:
        e = number("--youngs", text.strip()[:-2] if si else text, float)
        if si:
            phys = {k: number(f, given[f], float) for f, k in (("--density", "density"),
                                                                ("--diameter", "diameter"))
                    if f in given}
            return HertzContact.from_si(e, **phys, **kw)
        return HertzContact(e, **kw)
    except PecletArgumentError as exc:
        flag = {"youngs": "--youngs", "poisson": "--poisson", "density": "--density",
                "diameter": "--diameter", "rayleigh_fraction": "--rayleigh-fraction"}
        raise PecletArgumentError(flag.get(exc.argument, exc.argument),
                                  str(exc).split(" must be ", 1)[-1].rsplit(", got", 1)[0],
                                  exc.value) from None
