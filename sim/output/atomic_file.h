#pragma once
// The one way the simulator writes a file (frames, previews, meshes, a resumed run's statistics,
// checkpoints): the content goes to PATH.tmp, which is fsynced, renamed onto PATH, and the folder
// fsynced. A crash or a full disk leaves the old file or the new one, never half of one; on failure
// the .tmp is removed and the error names the file and the cause.
#include <functional>
#include <string>
#include <string_view>

namespace stokes::sim {
inline namespace output {

/// Writes `path` atomically and durably. `fill(tmp)` creates and fills the file `tmp`, throwing
/// (any std::exception) when it cannot. Throws std::runtime_error "<what>: cannot write '<path>':
/// <cause>".
void writeFileAtomically(const std::string& path, const std::string& what,
                         const std::function<void(const std::string& tmp)>& fill);

/// writeFileAtomically with `bytes` as the content.
void writeBytesAtomically(const std::string& path, const std::string& what, std::string_view bytes);

}  // namespace output
}  // namespace stokes::sim
