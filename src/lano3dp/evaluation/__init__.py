"""Evaluation: a checkpoint's closed-loop episodes, and one instruction end to end.

    config        EvalConfig, RunConfig, PerceptionSettings, GuidanceChoice (a preset + overrides), config files
    bundle        PolicyBundle: the policy, its observation spec, task and guidance tuning, loaded once
    episodes      EpisodeRunner: env + runner in one process, episodes by seed
    pool          episodes in this process or spawned workers
    results       summaries, the resumable episode log, the results file's shape (with provenance)
    evaluator     evaluate(EvalConfig) -> results
    instruction   run_instruction(RunConfig) with any decomposer
"""

from lano3dp.evaluation.bundle import PolicyBundle, PolicyTaskMismatchError
from lano3dp.evaluation.config import (
    DEFAULT_EVAL_SEED,
    EvalConfig,
    GuidanceChoice,
    PerceptionSettings,
    RunConfig,
    load_config_file,
    with_assignments,
)
from lano3dp.evaluation.evaluator import evaluate, evaluation_identity, evaluation_seeds
from lano3dp.evaluation.instruction import run_instruction
from lano3dp.evaluation.results import EpisodeLog, episode_log_path, summarize

__all__ = ["DEFAULT_EVAL_SEED", "EpisodeLog", "EvalConfig", "GuidanceChoice", "PerceptionSettings", "PolicyBundle",
           "PolicyTaskMismatchError", "RunConfig", "episode_log_path", "evaluate", "evaluation_identity",
           "evaluation_seeds", "load_config_file", "run_instruction", "summarize", "with_assignments"]
