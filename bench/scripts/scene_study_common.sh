# Shared by the scene study scripts (sourced, not run; needs ROOT, the repository, and TMP, a
# temporary folder):
#   scene_with SCENE PRECONDITIONER [METHOD] -> the path of a copy of scenes/SCENE.json whose solver
#   uses PRECONDITIONER (auto, jacobi, multigrid, ...) and, if given, the multigrid steps' Krylov
#   METHOD (solver.multigrid_method: auto, gmres, minres, ...), its mesh paths made absolute.
scene_with() {
  local method=${3:-auto}
  python3 - "$ROOT/scenes/$1.json" "$2" "$method" "$TMP/$1_$2_$method.json" <<'PY'
import json, os, sys
src, pre, method, dst = sys.argv[1:]
j = json.load(open(src))
j.setdefault("solver", {})["preconditioner"] = pre
j["solver"]["multigrid_method"] = method
for shape in j.get("liquid", []) + j.get("solids", []):
    if "file" in shape:
        shape["file"] = os.path.normpath(os.path.join(os.path.dirname(src), shape["file"]))
json.dump(j, open(dst, "w"), indent=1)
PY
  echo "$TMP/$1_$2_$method.json"
}
