"""Speed-accuracy studies: sweep foveated configurations and uniform baselines over scenes,
measure time and quality against a reference, and plot Pareto fronts.

``foveated-mi study STUDY.toml`` and :func:`run_study` (for notebooks) run a study file (layout:
:mod:`foveated_mi.study.spec`). Modules, one concern each:

* :mod:`~foveated_mi.study.spec`: the TOML schema and its validation;
* :mod:`~foveated_mi.study.tasks`: task expansion and the per-task worker functions;
* :mod:`~foveated_mi.study.executors`: ``local`` and Dask ``distributed`` execution;
* :mod:`~foveated_mi.study.results`: ``results.csv`` streaming and resume;
* :mod:`~foveated_mi.study.pareto`: Pareto fronts, plots and the front table;
* :mod:`~foveated_mi.study.runner`: :func:`run_study`, tying them together.
"""
from .pareto import front_table, pareto_figure, pareto_front, plot_pareto, scene_fronts
from .results import columns, read_rows
from .runner import StudyResult, run_study
from .spec import SceneSpec, StudySpec, load_study, parse_study

__all__ = ["run_study", "StudyResult", "load_study", "parse_study", "StudySpec", "SceneSpec",
           "pareto_front", "scene_fronts", "plot_pareto", "pareto_figure", "front_table",
           "read_rows", "columns"]
