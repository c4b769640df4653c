# The ROS-free core's sources, one list for every build of it (CMakeLists.txt's library and
# fuzz/CMakeLists.txt's sanitized copy): a file added here is built everywhere.
set(ROVER_CORE_SOURCES
  types.cpp
  alignment.cpp
  drift.cpp
  condensed.cpp
  condensed6.cpp
  place_graph.cpp
  pose_graph.cpp
  keyframe_intake.cpp
  trial_solve.cpp
  condensed_trial.cpp
  condensed_trial6.cpp
  graph_uncertainty.cpp
  global_pass.cpp
  batch_solve.cpp
  decision.cpp
  decision_rule.cpp
  held_candidates.cpp
  cycle_test.cpp
  parameters.cpp
  verdict_emitter.cpp
  verifier.cpp
  revocation.cpp
  global_release.cpp
  verdict_csv.cpp
)
