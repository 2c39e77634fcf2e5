# Copyright 2026 worm_gear_sim developers
# Licensed under the Apache License, Version 2.0
"""Live adaptation of the drive model from the encoders (pure core, no rclpy).

* :mod:`.estimator`: the online estimator (a Kalman filter with random-walk parameters on
  the residual measured - predicted theta4, regressors = the model's sensitivities) and
  the rule that decides when an adapted set may replace the model in use;
* :mod:`.live`: the glue the node and the offline twin share: measured samples in (checked,
  counted), the predictor's model updated in bounded steps, refusals said once;
* :mod:`.twin`: the offline twin (``worm-gear-sim adapt``): a scenario streamed through
  the real-time pipeline, a simulated plant, its encoder back to the adapter.

docs/adaptation.md explains the choices.  Import from the modules (no re-exports).
"""
