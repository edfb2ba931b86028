"""What a pack run writes: STL / VTU / CSV exports (``export``, which gathers
``resolution``, ``meshing``, ``stl``, ``vtu`` and ``transforms``), the page's figures
(``figures``), the bed's figures (``bed_figures``) and the bed report (``report``). Figures are
drawn through :mod:`peclet.core.figures` (the user's matplotlib backend is left alone)."""
