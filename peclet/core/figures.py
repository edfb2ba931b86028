"""The one way peclet draws a figure: a :class:`matplotlib.figure.Figure` on its own
:class:`~matplotlib.backends.backend_agg.FigureCanvasAgg`, never through ``pyplot``.

So producing a figure leaves the user's matplotlib backend (``matplotlib.get_backend()``) and
pyplot's figure list as they were (a notebook keeps its inline backend, a GUI session its
windows), and nothing has to be closed afterwards. :func:`save_png` writes atomically
(:func:`peclet.core.files.atomic_write`).
"""
from __future__ import annotations

from .files import atomic_write

__all__ = ["new_figure", "subplots", "save_png"]


def new_figure(figsize=None, dpi=None, **kw):
    """A Figure (``figsize`` inches, ``dpi``; other keywords to ``Figure``) on its own Agg
    canvas: pyplot's registry and the global backend are not involved."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if dpi is not None:
        kw["dpi"] = dpi
    fig = Figure(figsize=figsize, **kw)
    FigureCanvasAgg(fig)
    return fig


def subplots(nrows=1, ncols=1, figsize=None, dpi=None, squeeze=True, **kw):
    """(figure, axes) as ``pyplot.subplots`` gives them, on :func:`new_figure`'s canvas."""
    fig = new_figure(figsize, dpi)
    return fig, fig.subplots(nrows, ncols, squeeze=squeeze, **kw)


def save_png(fig, path, **savefig_kw):
    """Write ``fig`` as PNG to ``path`` atomically (``savefig_kw`` to ``Figure.savefig``, e.g.
    ``dpi``, ``bbox_inches``); returns the path."""
    return atomic_write(path, lambda tmp: fig.savefig(tmp, format="png", **savefig_kw))
