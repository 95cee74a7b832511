"""One closed-loop run: build the plant and controller, drive the loop, inject faults, summarise (design §9).

Importing the package registers the resolver of ``formation.scale/time_scale = "auto"`` with the scenario loader
(:func:`bioform_mj.scenario.loader.register_auto_scale`): "auto" needs a run of the scenario's demand; the
opt-in gain sizing (design §14.4) with the controller's builder (:func:`bioform_mj.control.params.register_sizing`):
it reads robot check's identification; and the plant registry's kinds with the scenario's validation
(:func:`bioform_mj.scenario.check.register_plant_kinds`): ``plant.kind`` may name any registered plant (the shipped
factories are registered by :mod:`bioform_mj.run.simulate`, the loop that builds the plants); and it imports the loop,
which registers itself with the demand (:func:`bioform_mj.run.demand.register_loop`): a run's demand check, the batch
engine's and the "auto" time scale run the demand's ideal twin on it."""

from bioform_mj.assess import learner_sizing as learner_sizing
from bioform_mj.plants.registry import plant_kinds as _plant_kinds
from bioform_mj.run import auto_scale as auto_scale
from bioform_mj.run import simulate as simulate
from bioform_mj.scenario.check import register_plant_kinds as _register_plant_kinds

_register_plant_kinds(_plant_kinds)
