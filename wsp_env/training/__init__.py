"""Training: ``wsp-env train`` with stable-baselines3 (``train``), the imitation warm start
(``imitation``) and the ONNX export of a trained policy (``export``)."""
