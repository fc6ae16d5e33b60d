#include "mcstat/exr-deep/codec/detail/fd_stream.h"

#include <OpenEXR/Iex.h>
#include <OpenEXR/ImfThreading.h>
#include <errno.h>
#include <unistd.h>

#include <algorithm>
#include <cstring>

#include "mcstat/core/parallel.h"

namespace mcstat::detail {

void Fd::reset() {
    if (fd_ >= 0) ::close(fd_);
    fd_ = -1;
}

std::string Fd::close() {
    if (fd_ < 0) return {};
    const int rc = ::close(fd_);
    fd_ = -1;
    return rc == 0 ? std::string() : std::string(std::strerror(errno));
}

int codecThreads(int nthreads) {
    const int n = std::min(kMaxCodecThreads, mcstat::threadCount(nthreads));
    if (n > 1 && Imf::globalThreadCount() == 0) setOpenExrThreads(n);
    return n;
}

void setOpenExrThreads(int threads) { Imf::setGlobalThreadCount(threads > 1 ? threads : 0); }

int64_t preadFull(int fd, void* buf, uint64_t n, uint64_t offset) {
    auto* p = static_cast<char*>(buf);
    uint64_t done = 0;
    while (done < n) {
        const ssize_t r = ::pread(fd, p + done, n - done, off_t(offset + done));
        if (r < 0) {
            if (errno == EINTR) continue;
            return -1;
        }
        if (r == 0) break;
        done += uint64_t(r);
    }
    return int64_t(done);
}

FdIStream::FdIStream(int fd, const std::string& name, uint64_t size)
    : Imf::IStream(name.c_str()), fd_(fd), size_(size) {}

bool FdIStream::read(char c[], int n) {
    if (n < 0) throw Iex::InputExc("negative read size");
    if (pos_ > size_ || uint64_t(n) > size_ - pos_) throw Iex::InputExc("Unexpected end of file.");
    const int64_t r = preadFull(fd_, c, uint64_t(n), pos_);
    if (r < 0) Iex::throwErrnoExc();
    if (r != n) throw Iex::InputExc("Unexpected end of file.");
    pos_ += uint64_t(n);
    return true;  // as Imf::StdIFStream: end of file is reported by throwing
}

FdOStream::FdOStream(int fd, const std::string& name) : Imf::OStream(name.c_str()), fd_(fd) {}

void FdOStream::write(const char c[], int n) {
    uint64_t done = 0;
    while (done < uint64_t(n)) {
        const ssize_t r = ::pwrite(fd_, c + done, uint64_t(n) - done, off_t(pos_ + done));
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) {
            const int e = r < 0 ? errno : ENOSPC;
            if (error_.empty()) error_ = std::strerror(e);
            Iex::throwErrnoExc("%T", e);
        }
        done += uint64_t(r);
    }
    pos_ += done;
}

}  // namespace mcstat::detail
