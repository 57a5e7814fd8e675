// The Python module `stokesvdb` (pybind11): scenes, a simulation advanced by frames, its particles
// and level set as numpy arrays, its statistics as dicts, frames, checkpoints and whole runs.
//
//   import stokesvdb
//   scene = stokesvdb.load_scene("scenes/default.json", resolution=24, frames=4)
//   sim = stokesvdb.Simulation(scene)
//   for step in sim.advance(frames=2, progress=lambda s: print(s["step"], s["iterations"])): ...
//   x, v = sim.particles()                 # (N, 3) float64 arrays
//   phi = sim.level_set()                  # dict: values (nx, ny, nz) float32, origin, dx
//   sim.write_frame("out")                 # out/frame_0002.vdb: "surface", "vel", metadata
//   stokesvdb.run(scene, "out", progress=print)  # the `stokesvdb run` loop: frames, stats.csv, ...
//
// Errors raise the command line's messages: a bad scene stokesvdb.SceneError (a ValueError), a
// step that fails for good RuntimeError. Ctrl-C raises KeyboardInterrupt at the next Krylov
// iteration; the simulation is then at its last complete step (the interrupted one is rolled
// back), so advance() may be called again and continues as if never stopped.
#include <pybind11/functional.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <omp.h>

#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "sim/output/frame_writer.h"
#include "sim/run/checkpoint.h"
#include "sim/run/scene_runner.h"
#include "sim/scene/scene.h"
#include "sim/step/simulator.h"

namespace py = pybind11;
using namespace stokes::sim;

namespace {

/// One step's statistics as a dict: the stats.csv columns (sim/run/scene_runner.h statsColumns).
py::dict statsDict(const StepStats& s) {
  py::dict d;
  for (const auto& [name, value] : statsRow(s)) d[py::str(name)] = value;
  d["solver"] = s.grid.solver;
  return d;
}

/// A stop request that Python's signal handlers answer: PyErr_CheckSignals runs them (the GIL is
/// held), and a KeyboardInterrupt they raise stays set until the call returns to Python. After it
/// no Python code is called (the progress callback is skipped).
class PythonInterrupt {
 public:
  bool requested() {
    if (!raised_ && PyErr_CheckSignals() != 0) raised_ = true;
    return raised_;
  }
  bool raised() const { return raised_; }
  /// Raises the pending exception in Python, if a signal handler set one.
  void rethrow() const {
    if (raised_) throw py::error_already_set();
  }

 private:
  bool raised_ = false;
};

py::array_t<double> vectors(const std::vector<Vec3d>& v) {
  py::array_t<double> a({py::ssize_t(v.size()), py::ssize_t(3)});
  auto m = a.mutable_unchecked<2>();
  for (std::size_t i = 0; i < v.size(); ++i)
    for (int k = 0; k < 3; ++k) m(py::ssize_t(i), k) = v[i][k];
  return a;
}

/// A simulation of one scene, advanced frame by frame.
class Simulation {
 public:
  explicit Simulation(const Scene& scene) : sim_(scene) {}

  /// Steps `frames` frames; progress(dict) after every step. Returns the steps' dicts.
  py::list advance(int frames, const std::optional<py::function>& progress) {
    if (frames < 0) throw py::value_error("advance: frames must be >= 0, got " + std::to_string(frames));
    py::list steps;
    PythonInterrupt interrupt;
    const auto onStep = [&](const StepStats& s) {
      py::dict d = statsDict(s);
      steps.append(d);
      if (progress && !interrupt.raised()) (*progress)(d);
    };
    for (int k = 0; k < frames; ++k) {
      bool complete = false;
      try {
        complete = sim_.advanceFrame(frame_ + 1, onStep, [&] { return interrupt.requested(); });
      } catch (const StepInterrupted&) {
        complete = false;  // the interrupted step is rolled back
      }
      if (!complete) {
        interrupt.rethrow();
        throw std::logic_error("advance: stopped without a request");
      }
      ++frame_;
    }
    return steps;
  }

  py::tuple particles() const {
    const ParticleSet<kSimDim> p = sim_.gatheredParticles();
    return py::make_tuple(vectors(p.x), vectors(p.v));
  }

  /// The liquid level set, dense over its active voxels: values[i, j, k] at the world position
  /// origin + dx (i, j, k); outside the band the values are +-background.
  py::dict levelSet() const {
    const openvdb::FloatGrid::Ptr phi = sim_.liquidLevelSet();
    py::dict d;
    const openvdb::CoordBBox box = phi ? phi->evalActiveVoxelBoundingBox() : openvdb::CoordBBox();
    const openvdb::Coord size = box.empty() ? openvdb::Coord(0) : box.dim();
    py::array_t<float> values({py::ssize_t(size.x()), py::ssize_t(size.y()), py::ssize_t(size.z())});
    auto m = values.mutable_unchecked<3>();
    if (!box.empty()) {
      const auto acc = phi->getConstAccessor();
      for (int i = 0; i < size.x(); ++i)
        for (int j = 0; j < size.y(); ++j)
          for (int k = 0; k < size.z(); ++k) m(i, j, k) = acc.getValue(box.min().offsetBy(i, j, k));
    }
    const openvdb::Vec3d origin = phi && !box.empty() ? phi->indexToWorld(box.min()) : openvdb::Vec3d(0.0);
    d["values"] = values;
    d["origin"] = py::make_tuple(origin.x(), origin.y(), origin.z());
    d["dx"] = phi ? phi->voxelSize().x() : sim_.scene().dx();
    d["background"] = phi ? double(phi->background()) : 0.0;
    return d;
  }

  /// Writes DIR/frame_NNNN.vdb (and .ply / .png as the scene's output asks) of the state now.
  std::string writeFrame(const std::string& dir) const {
    std::filesystem::create_directories(dir);
    FrameWriter(sim_, dir).write(frame_);
    return framePath(dir, frame_, "vdb");
  }

  /// Writes a checkpoint of the state into DIR/checkpoints (sim/run/checkpoint.h); returns its path.
  std::string checkpoint(const std::string& dir) const {
    RunCheckpoint c;
    c.signature = runSignature(sim_.scene(), "python");
    c.progress.framesWritten = frame_;
    c.state = sim_.state();
    return writeCheckpoint(dir, c);
  }

  /// A simulation of `scene` at the newest checkpoint in DIR (written by checkpoint()).
  static std::unique_ptr<Simulation> resume(const Scene& scene, const std::string& dir) {
    const auto newest = findNewestCheckpoint(dir);
    if (!newest) throw py::value_error("resume: no checkpoint in " + checkpointFolder(dir));
    if (newest->second.signature != runSignature(scene, "python"))
      throw py::value_error("resume: " + newest->first + " is a checkpoint of another scene or run");
    auto s = std::make_unique<Simulation>(scene);
    s->sim_.restore(newest->second.state);
    s->frame_ = newest->second.progress.framesWritten;
    return s;
  }

  double time() const { return sim_.time(); }
  int frame() const { return frame_; }
  int steps() const { return sim_.stepsTaken(); }
  const Scene& scene() const { return sim_.scene(); }

 private:
  Simulator sim_;
  int frame_ = 0;  ///< frames completed
};

Scene sceneFromFile(const std::string& path, std::optional<int> resolution, std::optional<int> frames) {
  return stokes::sim::loadScene(path, SceneOverrides{resolution, frames});
}

Scene sceneFromDict(const py::dict& scene, const std::string& baseDir, std::optional<int> resolution,
                    std::optional<int> frames) {
  const std::string text = py::module_::import("json").attr("dumps")(scene).cast<std::string>();
  return parseSceneText(text, "scene dict", baseDir, SceneOverrides{resolution, frames});
}

/// The `stokesvdb run` loop (sim/run/scene_runner.h) with a progress callback; returns the summary.
py::dict runWhole(const Scene& scene, const std::string& outDir, const std::optional<py::function>& progress,
             bool resume) {
  PythonInterrupt interrupt;
  RunOptions options;
  options.outDir = outDir;
  options.resume = resume;
  options.signature = runSignature(scene, "python");
  options.onStep = [&](const StepStats& s) {
    if (progress && !interrupt.raised()) (*progress)(statsDict(s));
  };
  options.stopRequested = [&] { return interrupt.requested(); };
  const RunSummary r = runScene(scene, options);
  interrupt.rethrow();
  py::dict d;
  d["frames"] = r.frames;
  d["steps"] = r.steps;
  d["steps_total"] = r.stepsTotal;
  d["retried_steps"] = r.retriedSteps;
  d["wall_seconds"] = r.wallSeconds;
  d["initial_volume"] = r.initialVolume;
  d["final_volume"] = r.finalVolume;
  d["max_iterations"] = r.maxIterations;
  d["last_checkpoint"] = r.lastCheckpoint;
  d["resumed_from_step"] = r.resumedFromStep;
  return d;
}

}  // namespace

PYBIND11_MODULE(stokesvdb, m) {
  m.doc() = "StokesVDB: variational Stokes for highly viscous liquids on OpenVDB grids";
  m.attr("__version__") = STOKES_VERSION;
  py::register_exception<SceneError>(m, "SceneError", PyExc_ValueError);
  py::register_exception<SimulationError>(m, "SimulationError", PyExc_RuntimeError);
  py::register_exception<ResumeError>(m, "ResumeError", PyExc_RuntimeError);

  py::class_<Scene>(m, "Scene", "A validated scene (scenes/README.md)")
      .def_readonly("name", &Scene::name)
      .def_readonly("resolution", &Scene::resolution)
      .def_readonly("frames", &Scene::frames)
      .def_readonly("fps", &Scene::fps)
      .def_property_readonly("dx", &Scene::dx)
      .def_property_readonly("cells", [](const Scene& s) {
        const openvdb::Coord c = s.resolutionCells();
        return py::make_tuple(c.x(), c.y(), c.z());
      });

  m.def("load_scene", &sceneFromFile, py::arg("path"), py::arg("resolution") = py::none(),
        py::arg("frames") = py::none(),
        "A scene file; resolution and frames override the file's (checked against the same limits)");
  m.def("scene_from_dict", &sceneFromDict, py::arg("scene"), py::arg("base_dir") = ".",
        py::arg("resolution") = py::none(), py::arg("frames") = py::none(),
        "A scene from a dict of the scene file's keys; mesh paths are relative to base_dir");
  m.def("run", &runWhole, py::arg("scene"), py::arg("out_dir"), py::arg("progress") = py::none(),
        py::arg("resume") = false,
        "Runs every frame of the scene into out_dir (frames, stats.csv, checkpoints) as `stokesvdb run`; "
        "progress(dict) after every step; returns the summary");
  m.def("set_threads", [](int n) { omp_set_num_threads(n); }, py::arg("threads"), "OpenMP threads for what follows");

  py::class_<Simulation>(m, "Simulation", "A simulation of one scene, advanced frame by frame")
      .def(py::init<const Scene&>(), py::arg("scene"))
      .def("advance", &Simulation::advance, py::arg("frames") = 1, py::arg("progress") = py::none(),
           "Steps that many frames; progress(dict) after every step; returns the steps' stats dicts")
      .def("particles", &Simulation::particles, "(positions, velocities), each an (N, 3) float64 array")
      .def("level_set", &Simulation::levelSet,
           "The liquid level set, dense over its active voxels: dict(values, origin, dx, background)")
      .def("write_frame", &Simulation::writeFrame, py::arg("dir"),
           "Writes DIR/frame_NNNN.vdb (and the scene's .ply / .png) of the state now; returns its path")
      .def("checkpoint", &Simulation::checkpoint, py::arg("dir"), "Writes a checkpoint; returns its path")
      .def_static("resume", &Simulation::resume, py::arg("scene"), py::arg("dir"),
                  "The simulation at the newest checkpoint in dir")
      .def_property_readonly("time", &Simulation::time)
      .def_property_readonly("frame", &Simulation::frame)
      .def_property_readonly("steps", &Simulation::steps)
      .def_property_readonly("scene", &Simulation::scene);
}
