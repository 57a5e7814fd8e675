# Shared scaffolding of the analytic study scripts (sourced, not run):
#   DEFAULT_CASES=(...); args_of() { case name -> `stokesvdb analytic` arguments; }
#   source "$(dirname "$0")/study_common.sh" "$@"
# sets B (the binary, $STOKESVDB or build/bin/stokesvdb), THREADS, REPS and CASES from
# [threads] [reps] [cases...], and defines run CASE [options...]: REPS JSON lines of
# `stokesvdb analytic` at relative residual 1e-8.
B=${STOKESVDB:-build/bin/stokesvdb}
THREADS=${1:-1}
REPS=${2:-3}
shift 2 || true
CASES=("$@")
[ ${#CASES[@]} -eq 0 ] && CASES=("${DEFAULT_CASES[@]}")
run() {
  for _ in $(seq "$REPS"); do "$B" analytic $(args_of "$1") --tol 1e-8 --threads "$THREADS" --json "${@:2}"; done
}
for c in "${CASES[@]}"; do args_of "$c" > /dev/null || exit 2; done  # an unknown case stops here, named
