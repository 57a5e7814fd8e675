// Progress of a run: see run_progress.h.
#include "sim/run/run_progress.h"
#include "solver/krylov/stopwatch.h"

#include <sys/resource.h>

#include <cmath>
#include <cstdio>
#include <ostream>

namespace stokes::sim {
inline namespace run {

namespace {

std::string formatDuration(double s) {
  char buf[32];
  if (!std::isfinite(s)) return "?";
  if (s < 60.0) std::snprintf(buf, sizeof buf, "%.0fs", s);
  else if (s < 3600.0) std::snprintf(buf, sizeof buf, "%dm%02ds", int(s) / 60, int(s) % 60);
  else std::snprintf(buf, sizeof buf, "%dh%02dm", int(s) / 3600, (int(s) % 3600) / 60);
  return buf;
}

}  // namespace

RunProgressLine::RunProgressLine(std::ostream* out, bool terminal, std::string sceneName, int frames, double duration,
                                 double startTime)
    : out_(out),
      terminal_(terminal),
      name_(std::move(sceneName)),
      frames_(frames),
      duration_(duration),
      startTime_(startTime),
      start_(std::chrono::steady_clock::now()) {}

double RunProgressLine::elapsed() const {
  return solver::secondsSince(start_);
}

std::string RunProgressLine::eta(double t) const {
  // the rate of simulated time in this process so far, over what remains
  const double done = t - startTime_;
  return formatDuration(done > 0.0 ? elapsed() / done * (duration_ - t) : NAN);
}

void RunProgressLine::add(const char* name, const std::optional<double>& seconds) {
  if (!seconds) return;
  for (auto& [n, s] : stages_)
    if (n == name) {
      s += *seconds;
      return;
    }
  stages_.emplace_back(name, *seconds);
}

void RunProgressLine::step(const StepStats& s) {
  for (const Stage stage : kStages) add(stageName(stage), s.times[stage]);
  ++frameSteps_;
  frameMaxIterations_ = std::max(frameMaxIterations_, s.grid.iterations);
  particles_ = s.particles;
  if (!out_) return;
  for (const std::string& failure : s.failedAttempts)
    note("[" + name_ + "] step " + std::to_string(s.step) + " retried with half the step after: " + failure);
  if (!terminal_) return;
  const auto now = std::chrono::steady_clock::now();
  if (lineOpen_ && now - lastDraw_ < std::chrono::milliseconds(100)) return;
  lastDraw_ = now;
  char line[256];
  std::snprintf(line, sizeof line, "\r\033[K[%s] frame %d/%d step %d t=%.4f s iters=%d particles=%zu | %s, ETA %s",
                name_.c_str(), s.frame, frames_, s.step, s.t, s.grid.iterations, s.particles,
                formatDuration(elapsed()).c_str(), eta(s.t).c_str());
  *out_ << line << std::flush;
  lineOpen_ = true;
}

void RunProgressLine::frameWritten(int frame, double time) {
  if (out_ && !terminal_) {
    char line[256];
    std::snprintf(line, sizeof line,
                  "[%s] frame %d/%d t=%.4f s: %d steps, at most %d iterations, %zu particles | %s, ETA %s\n", name_.c_str(),
                  frame, frames_, time, frameSteps_, frameMaxIterations_, particles_, formatDuration(elapsed()).c_str(),
                  eta(time).c_str());
    *out_ << line << std::flush;
  }
  frameSteps_ = 0;
  frameMaxIterations_ = 0;
}

void RunProgressLine::note(const std::string& text) {
  if (!out_) return;
  if (lineOpen_) *out_ << "\r\033[K";
  *out_ << text << "\n" << std::flush;
  lineOpen_ = false;
}

void RunProgressLine::finish() {
  if (out_ && lineOpen_) *out_ << "\n" << std::flush;
  lineOpen_ = false;
}

std::size_t peakResidentBytes() {
  rusage u{};
  if (getrusage(RUSAGE_SELF, &u) != 0) return 0;
  return std::size_t(u.ru_maxrss) * 1024;  // Linux reports kilobytes
}

}  // namespace run
}  // namespace stokes::sim
