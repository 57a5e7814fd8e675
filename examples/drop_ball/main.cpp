// The solver as a library: a viscous ball dropped into a box, stepped through StokesVDB's
// simulator (sim/step/simulator.h) without the command line. Prints the frame, its steps and the
// liquid volume; exits 1 if the volume drifts by more than 1% (the scene keeps it).
#include <cmath>
#include <cstdio>

#include <stokesvdb/stokesvdb.h>

int main() {
  using namespace stokes::sim;
  const Scene scene = parseSceneText(R"({"name": "drop_ball",
      "domain": {"min": [0, 0, 0], "max": [0.2, 0.2, 0.2]}, "resolution": 16, "frames": 3,
      "material": {"density": 1400, "viscosity": 50}, "gravity": [0, -9.81, 0],
      "liquid": [{"shape": "sphere", "center": [0.1, 0.1, 0.1], "radius": 0.05}],
      "output": {"preview": false}})",
                                     "drop_ball", ".");
  Simulator sim(scene);
  const double target = sim.volumeTarget();
  double volume = 0.0;
  for (int frame = 1; frame <= scene.frames; ++frame) {
    int steps = 0;
    sim.advanceFrame(frame, [&](const StepStats& s) {
      ++steps;
      volume = s.liquidVolume;
    });
    std::printf("frame %d: t = %.4f s, %d steps, liquid volume %.6g m^3\n", frame, sim.time(), steps, volume);
  }
  const double drift = volume / target - 1.0;
  std::printf("volume drift %+.3f%%\n", 100.0 * drift);
  return std::abs(drift) < 0.01 ? 0 : 1;
}
