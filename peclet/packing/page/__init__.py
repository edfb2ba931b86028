"""The reference page end to end (``peclet pall-ring``): the pipeline (``pipeline.run``, Steps
1-7), its up-front checks (``checks``) and the wall-thickness sweep in a child process
(``sweep_process``)."""
