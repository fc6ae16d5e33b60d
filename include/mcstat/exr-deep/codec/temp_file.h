// Temporary files of atomic writes: every mcstat writer (statistics files, images, references,
// per-sample records) writes to a temporary name next to its target and renames it onto the
// target when complete, so a target is never half-written. This module names those temporaries,
// removes them when the write is abandoned, on SIGINT, SIGTERM and SIGHUP (once the tool asked
// for it), and when a later write to the same target finds ones left by a process that is gone
// (SIGKILL, power loss).
#pragma once

#include <string>

namespace mcstat {

/// The temporary file of one write to `target`:
///   "<dir>/.<name>.tmp-<pid>-<8 hex digits>-<host><suffix>"
/// (host: this machine's name, letters, digits and '_' only; `suffix` last, for writers that
/// choose a format by extension). Creating one first removes stale temporaries of `target`
/// (removeStaleTemporaries) and registers the new name for removal on a signal. The destructor
/// removes the file unless commit() renamed it. Not copyable.
class TemporaryFile {
  public:
    explicit TemporaryFile(const std::string& target, const std::string& suffix = "");
    ~TemporaryFile();
    TemporaryFile(const TemporaryFile&) = delete;
    TemporaryFile& operator=(const TemporaryFile&) = delete;

    const std::string& path() const { return path_; }
    const std::string& target() const { return target_; }
    /// Renames the temporary onto the target; false with `err` ("<target>: cannot rename ...").
    /// Either way the name is no longer registered.
    bool commit(std::string& err);
    /// Removes the temporary now (a failed write).
    void remove();

  private:
    std::string target_, path_;
    int slot_ = -1;  ///< in the signal-time registry, -1 when none was free
    bool done_ = false;
};

/// Writes `text` to `target` through a TemporaryFile renamed onto it (checkOutputTarget first), so
/// a table or report is never left half-written. False with a one-line `err` naming the target.
bool writeTextAtomically(const std::string& target, const std::string& text, std::string& err);

/// Whether a write may replace `target` by a rename: the name is not empty, its directory exists,
/// and `target` is absent or a regular file with a write permission bit. Anything else is refused
/// with a one-line `err` naming it: a directory; a device, FIFO or socket such as /dev/null or
/// /dev/full (a rename would replace the device node with a file); a read-only file (mcstat
/// refuses to replace it, even as root; oiiotool 2.4 replaces it, since it also writes a
/// temporary and renames). Every writer calls it before it creates its temporary.
bool checkOutputTarget(const std::string& target, std::string& err);

/// Removes the temporaries of `target` that a process of this machine left when it died: names
/// of TemporaryFile's form whose host is this machine and whose process no longer runs. Names of
/// earlier mcstat versions (".<name>.tmp-<pid>[-<hex>][.records]", the renderer's
/// ".<name>.tmp<pid>.exr") carry no host, so they are removed only when their process is gone
/// here and they were last written more than 15 minutes ago (on storage shared by several
/// machines the process may run elsewhere). Returns how many were removed.
int removeStaleTemporaries(const std::string& target);

/// Installs handlers for SIGINT, SIGTERM and SIGHUP that remove every registered temporary and
/// then end the process as the signal would have (the default action, re-raised). For tools'
/// main(): a library never installs signal handlers on its own. Idempotent.
void removeTemporariesOnSignals();

}  // namespace mcstat
