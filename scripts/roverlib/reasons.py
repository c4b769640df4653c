"""The verdict reasons: the strings a verdict's `reason` holds (LoopVerdict.reason, the `reason`
column of verdict logs). The C++ enum core::Reason and its names in core::toString(Reason)
(rover_loop_fusion/core/types.h, types.cpp) are the source; this is the one list in Python, which
everything under scripts/ imports. test/python/test_reasons.py checks it, the constants of
msg/LoopVerdict.msg and the table in docs/ros-api.md against the C++ enum."""

# reason -> what decided the verdict, in words; in the order the demo's summary lists them
NOTES = {
    "accepted": "score <= threshold, or released with its revisit",
    "innovation_above_bound": "innovation gate, no solve",
    "score_above_threshold": "deformation score > threshold",
    "not_converged": "trial solve did not converge",
    "time_budget_exceeded": "trial solve out of time",
    "no_trajectory_prior": "unconnected sequences: policy",
    "invalid_input": "bad input",
    "inconsistent_with_drift": "chi2: d2 above the gate",
    "lookalike_closer": "chi2: a look-alike place explains it better",
    "deferred": "held; a final verdict follows",
    "unconfirmed": "held, then dropped: not confirmed",
    "revoked": "an accepted loop removed again",
}
REASONS = tuple(NOTES)
# Verdicts whose score ranks the candidate (metrics.ranking_score): the trial solve converged and
# its score was compared with the threshold. Every other reason has no score to rank by.
SCORED = ("accepted", "score_above_threshold")
# Verdicts that ran a trial solve (bench/agreement.py).
TRIALLED = SCORED + ("not_converged",)
# The two reasons of a held candidate (LoopVerdict.msg): its deferred verdict, and its final one
# when it is dropped.
DEFERRED = "deferred"
UNCONFIRMED = "unconfirmed"
