"""One closed-loop run: build the plant and controller, drive the loop, inject faults, summarise (design §9).

Importing the package registers the resolver of ``formation.scale/time_scale = "auto"`` with the scenario loader
(:func:`bioform_mj.scenario.loader.register_auto_scale`): "auto" needs a run of the scenario's demand; and the
opt-in gain sizing (design §14.4) with the controller's builder (:func:`bioform_mj.control.params.register_sizing`):
it reads robot check's identification."""

from bioform_mj.assess import learner_sizing as learner_sizing
from bioform_mj.run import auto_scale as auto_scale
