"""Options shared by the subcommands that describe a bed (``pack``, ``ensemble``)."""

ELEMENT_HELP = ("library element (pall_ring, raschig_ring, berl_saddle, intalox_saddle, sphere, "
                "solid_cylinder) or a flat-encoding .npz (default pall_ring)")
CONTAINER_HELP = ("box:L (periodic) | column:N (diameter N D, floor at y = 0) | walled:Lx,Lz, "
                  "in element diameters D (default box:3.5, the page's)")


def add_bed_options(parser):
    """--element, --container and --protocol, with the page's defaults (values stay text: each
    command checks them before any work and names the flag in its one-line error)."""
    parser.add_argument("--element", default="pall_ring", help=ELEMENT_HELP)
    parser.add_argument("--container", default="box:3.5", help=CONTAINER_HELP)
    parser.add_argument("--protocol", default="page", help="page | rain (default page)")
