"""Many specimens of one joint design: the population of every joint parameter (docs/population.md).

* :mod:`~blackbox.population.likelihood` -- a specimen's likelihood of ``log k`` (quadratic or
  the exact profile, tabulated) and its integral against a log-normal population;
* :mod:`~blackbox.population.specimen` -- one specimen in its condensed model: the estimate and
  the likelihood of every parameter (no solver run after the condensation);
* :mod:`~blackbox.population.hierarchy` -- the population of one parameter: centre and spread
  with their intervals, the specimens shrunk toward it, the leave-one-out test;
* :mod:`~blackbox.population.fit` -- every parameter, the pooled test of whether the specimens
  differ, the specimens that do not belong;
* :mod:`~blackbox.population.coverage` -- coverage of the intervals over simulated populations.
"""

from blackbox.population.fit import PopulationFit, fit_population
from blackbox.population.hierarchy import ParameterPopulation, fit_parameter
from blackbox.population.specimen import SpecimenFit, fit_specimen

__all__ = ["PopulationFit", "fit_population", "ParameterPopulation", "fit_parameter", "SpecimenFit", "fit_specimen"]
