"""One closed-loop run: build the plant and controller, drive the loop, inject faults, summarise (design §9).

Importing the package registers the resolver of ``formation.scale/time_scale = "auto"`` with the scenario loader
(:func:`bioform_mj.scenario.loader.register_auto_scale`): "auto" needs a run of the scenario's demand."""

from bioform_mj.run import auto_scale as auto_scale
