"""Mission control: plan editing and the map (:mod:`~ui.mission.plan_editor`,
:mod:`~ui.mission.plan_map`), the runner on the GUI (:mod:`~ui.mission.controller`), progress
with thumbnails (:mod:`~ui.mission.progress`), manual set-up moves
(:mod:`~ui.mission.setup_panel`), all on the Mission page (:mod:`~ui.mission.page`)."""
