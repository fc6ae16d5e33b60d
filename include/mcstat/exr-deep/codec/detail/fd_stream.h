// Internal: OpenEXR streams over a POSIX file descriptor.
// FdIStream lets the header check (Core API) and the pixel read (C++ API) use one open file, so the
// file that was validated is the file that is read. FdOStream records write errors that OpenEXR
// would otherwise swallow (it writes the offset table in a destructor).
#pragma once

#include <OpenEXR/ImfIO.h>

#include <cstdint>
#include <string>

namespace mcstat::detail {

/// Owns a file descriptor; closes it on destruction.
class Fd {
  public:
    Fd() = default;
    explicit Fd(int fd) : fd_(fd) {}
    Fd(const Fd&) = delete;
    Fd& operator=(const Fd&) = delete;
    Fd(Fd&& o) noexcept : fd_(o.fd_) { o.fd_ = -1; }
    Fd& operator=(Fd&& o) noexcept {
        if (this != &o) {
            reset();
            fd_ = o.fd_;
            o.fd_ = -1;
        }
        return *this;
    }
    ~Fd() { reset(); }
    int get() const { return fd_; }
    void reset();
    /// Closes now and reports close()'s error as errno-style text ("" on success).
    std::string close();

  private:
    int fd_ = -1;
};

/// Reads `fd` with pread, within [0, size); throws Iex::InputExc past the end of file.
class FdIStream : public Imf::IStream {
  public:
    FdIStream(int fd, const std::string& name, uint64_t size);
    bool read(char c[], int n) override;
    uint64_t tellg() override { return pos_; }
    void seekg(uint64_t pos) override { pos_ = pos; }
    uint64_t size() const { return size_; }
    int fd() const { return fd_; }

  private:
    int fd_;
    uint64_t pos_ = 0;
    uint64_t size_;
};

/// Writes with pwrite; throws Iex::ErrnoExc on failure and remembers the first error.
class FdOStream : public Imf::OStream {
  public:
    FdOStream(int fd, const std::string& name);
    void write(const char c[], int n) override;
    uint64_t tellp() override { return pos_; }
    void seekp(uint64_t pos) override { pos_ = pos; }
    /// First write error ("" if none).
    const std::string& error() const { return error_; }

  private:
    int fd_;
    uint64_t pos_ = 0;
    std::string error_;
};

/// The number of threads OpenEXR should decode or encode a statistics file with: `nthreads`, or
/// all cores for 0, at most kMaxCodecThreads (each keeps a compressed and an uncompressed chunk of
/// every part in memory: about 10 MB each at 1920 pixels wide and M = 21). A process that never
/// sized OpenEXR's global pool (globalThreadCount() == 0, e.g. `mcstat`) would run every task on
/// one thread: the pool is then sized to that number; a pool the host sized (OIIO) is left alone.
int codecThreads(int nthreads);
inline constexpr int kMaxCodecThreads = 8;

/// Sizes OpenEXR's global thread pool (the C++ API's line-block codec threads) to `threads`, none
/// for 0 or 1 (the calling thread codes): the one place in mcstat that sizes it (codecThreads
/// when nothing did; mcstat-render for its writes).
void setOpenExrThreads(int threads);

/// Reads `n` bytes at `offset`; returns the number read (short at end of file), -1 on error.
int64_t preadFull(int fd, void* buf, uint64_t n, uint64_t offset);

}  // namespace mcstat::detail
