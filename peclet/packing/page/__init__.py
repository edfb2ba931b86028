"""The reference page end to end (``peclet pall-ring``): the pipeline (``pipeline.run``, Steps
1-7), its up-front checks (``checks``), the wall-thickness sweep in a child process
(``sweep_process``) and the Results table beside the page's (``table``)."""
