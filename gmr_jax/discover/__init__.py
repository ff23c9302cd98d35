"""Finding the physics a model left out (first step: the EMPS study, `_emps_study`)."""
