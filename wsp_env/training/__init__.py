"""Training: ``wsp-env train`` with stable-baselines3 (``train``, its config ``config``), the
imitation warm start (``imitation``) and the ONNX export of a trained policy (``export``)."""

# Models saved before the package had folders pickled their learning-rate schedule as
# ``wsp_env.training.LinearSchedule`` (the shipped policies among them): it stays loadable there.
from wsp_env.training.config import LinearSchedule

__all__ = ["LinearSchedule"]
