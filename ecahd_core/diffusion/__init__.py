"""Diffusion models of ECAHD: the SD / DD / FD denoisers, their schedule, sampling and training.

Modules, by question:
- ``scheduler``     the noise schedule q(x_t | x_0) and the DDIM step (Eqs. 1-2, Alg. 2 line 6)
- ``denoiser``      eps_theta: the Transformer of Fig. 2(a) (+ optional map encoder), the
                    temporal U-Net of the FD baseline, ``build_denoiser``
- ``conditioning``  inpainting of start / goal waypoints (``apply_conditioning``)
- ``guides``        the guide interface: cost J and its gradient (Alg. 2 lines 4-5)
- ``sampler``       the sampling loop: DDIM + guidance + inpainting (Alg. 2 lines 1-9)
- ``normalizer``    metres <-> normalised diffusion space
- ``training``      training (AdamW, warm-up, EMA, DDP) and checkpoints
"""
from ecahd_core.diffusion.conditioning import (START_GOAL, apply_conditioning, condition_mask,
                                               expand_conditions)
from ecahd_core.diffusion.denoiser import (DenoiserConfig, TemporalUnetDenoiser,
                                           TransformerDenoiser, build_denoiser)
from ecahd_core.diffusion.guides import CostGuide, Guide, GuideOutput
from ecahd_core.diffusion.normalizer import Normalizer
from ecahd_core.diffusion.sampler import (DiffusionSampler, SampleOutput, SamplerConfig,
                                          sample)
from ecahd_core.diffusion.scheduler import (DDIMScheduler, DDIMStepOutput, NoiseSchedule,
                                            ScheduleConfig)
from ecahd_core.diffusion.training import (Checkpoint, ModelKind, TrainConfig, TrainResult,
                                           load_checkpoint, train)
from ecahd_core.threads import PRECISIONS, native_bf16, resolve_precision

__all__ = [
    "START_GOAL", "apply_conditioning", "condition_mask", "expand_conditions",
    "DenoiserConfig", "TemporalUnetDenoiser", "TransformerDenoiser", "build_denoiser",
    "CostGuide", "Guide", "GuideOutput", "Normalizer",
    "DiffusionSampler", "SampleOutput", "SamplerConfig", "sample", "DDIMScheduler",
    "DDIMStepOutput", "NoiseSchedule", "ScheduleConfig", "Checkpoint", "ModelKind",
    "TrainConfig", "TrainResult", "load_checkpoint", "train", "PRECISIONS", "native_bf16",
    "resolve_precision",
]
