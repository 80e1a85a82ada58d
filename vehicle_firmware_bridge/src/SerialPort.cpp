#include <cpm/vehicle/SerialPort.hpp>

#include <cpm/Error.hpp>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <deque>
#include <fcntl.h>
#include <mutex>
#include <poll.h>
#include <stdlib.h>
#include <sys/eventfd.h>
#include <sys/file.h>
#include <sys/stat.h>
#include <sys/sysmacros.h>
#include <termios.h>
#include <thread>
#include <unistd.h>

namespace cpm::vehicle {
namespace {

speed_t baud_constant(int baud, const std::string& path)
{
    switch (baud) {
    case 9600: return B9600;
    case 19200: return B19200;
    case 38400: return B38400;
    case 57600: return B57600;
    case 115200: return B115200;
    case 230400: return B230400;
    case 460800: return B460800;
    case 921600: return B921600;
    case 1000000: return B1000000;
    case 2000000: return B2000000;
    default: throw Error(path + ": unsupported baud rate " + std::to_string(baud) +
                         " (use 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600, 1000000 or 2000000)");
    }
}

void make_raw(int fd, speed_t speed, const std::string& path)
{
    termios tio{};
    if (tcgetattr(fd, &tio) != 0) throw Error(path + ": not a terminal device (" + std::strerror(errno) + ")");
    cfmakeraw(&tio);
    tio.c_cflag |= CLOCAL | CREAD;
    tio.c_cflag &= ~(CRTSCTS | CSTOPB);
    tio.c_cc[VMIN] = 0;
    tio.c_cc[VTIME] = 0;
    cfsetispeed(&tio, speed);
    cfsetospeed(&tio, speed);
    if (tcsetattr(fd, TCSANOW, &tio) != 0) throw Error(path + ": cannot set raw mode (" + std::strerror(errno) + ")");
}

}  // namespace

SerialPort::SerialPort(const std::string& path, int baud)
{
    speed_t speed = baud_constant(baud, path);
    fd_ = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    if (fd_ < 0) {
        std::string message = path + ": cannot open the serial device (" + std::strerror(errno) + ")";
        if (errno == ENOENT || errno == ENODEV || errno == ENXIO || errno == EIO) throw DeviceUnavailable(message);
        throw Error(message);
    }
    // The lock first: a program refused the line must not have set its speed or mode under the
    // one that holds it.
    if (flock(fd_, LOCK_EX | LOCK_NB) != 0) {
        ::close(fd_);
        throw DeviceUnavailable(path + ": in use by another program (it holds the device's lock)");
    }
    try {
        make_raw(fd_, speed, path);
    } catch (...) {
        ::close(fd_);
        throw;
    }
    tcflush(fd_, TCIOFLUSH);
    struct stat st{};
    // UNIX 98 pty slaves have major numbers 136..143 (Documentation/admin-guide/devices.txt).
    pty_ = fstat(fd_, &st) == 0 && S_ISCHR(st.st_mode) && major(st.st_rdev) >= 136 && major(st.st_rdev) <= 143;
}

void SerialPort::check_baud(int baud, const std::string& path) { baud_constant(baud, path); }

SerialPort::~SerialPort()
{
    if (fd_ >= 0) ::close(fd_);
}

long SerialPort::read_some(uint8_t* data, size_t size, int timeout_ms)
{
    pollfd p{fd_, POLLIN, 0};
    int n = ::poll(&p, 1, timeout_ms);
    if (n < 0) return errno == EINTR ? 0 : -1;
    if (n == 0) return 0;
    if (p.revents & POLLIN) {
        ssize_t got = ::read(fd_, data, size);
        if (got > 0) return got;
        if (got < 0 && (errno == EAGAIN || errno == EINTR)) return 0;
        return -1;  // EOF or EIO: the other side is gone
    }
    return (p.revents & (POLLHUP | POLLERR | POLLNVAL)) ? -1 : 0;
}

bool SerialPort::write_all(const uint8_t* data, size_t size)
{
    size_t done = 0;
    int waits = 0;
    while (done < size) {
        ssize_t n = ::write(fd_, data + done, size - done);
        if (n > 0) {
            done += size_t(n);
            continue;
        }
        if (n < 0 && (errno == EAGAIN || errno == EINTR) && waits++ < 10) {
            pollfd p{fd_, POLLOUT, 0};
            ::poll(&p, 1, 2);
            continue;
        }
        return false;
    }
    return true;
}

bool SerialPort::discard_output() { return tcflush(fd_, TCOFLUSH) == 0; }

PseudoTerminal::PseudoTerminal(const std::string& link_path) : link_path_(link_path)
{
    master_ = posix_openpt(O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (master_ < 0 || grantpt(master_) != 0 || unlockpt(master_) != 0) {
        throw Error(std::string("cannot create a pseudo-terminal (") + std::strerror(errno) + ")");
    }
    char name[128];
    if (ptsname_r(master_, name, sizeof name) != 0) throw Error("ptsname failed");
    slave_path_ = name;
    slave_ = ::open(name, O_RDWR | O_NOCTTY | O_CLOEXEC);
    if (slave_ < 0) throw Error(slave_path_ + ": cannot open (" + std::strerror(errno) + ")");
    make_raw(slave_, B115200, slave_path_);
    fcntl(master_, F_SETFL, fcntl(master_, F_GETFL) | O_NONBLOCK);
    if (!link_path_.empty()) {
        ::unlink(link_path_.c_str());
        if (::symlink(slave_path_.c_str(), link_path_.c_str()) != 0) {
            throw Error(link_path_ + ": cannot create the device link (" + std::strerror(errno) + ")");
        }
    }
}

/// The thread of read_on_own_thread and what it has read.
struct PseudoTerminal::Reader
{
    static constexpr size_t kCapacity = 64 * 1024;
    std::mutex mutex;
    std::deque<uint8_t> bytes;
    bool failed = false;
    int stop_fd = -1;
    std::thread thread;

    void run(int master, Realtime mode, int priority)
    {
        const RealtimeThread realtime(mode, priority, "the simulated controller's line reader");
        pollfd fds[2] = {{master, POLLIN, 0}, {stop_fd, POLLIN, 0}};
        uint8_t buffer[512];
        for (;;) {
            size_t room = 0;
            {
                std::lock_guard<std::mutex> lock(mutex);
                room = kCapacity - std::min(kCapacity, bytes.size());
            }
            const bool full = room == 0;
            fds[0].events = full ? 0 : POLLIN;  // full: only a stop ends the wait, 1 ms at a time
            const int ready = ::poll(fds, 2, full ? 1 : -1);
            if (ready < 0 && errno != EINTR) break;
            if (fds[1].revents != 0) return;
            if (ready <= 0 || full) continue;
            if (fds[0].revents & POLLIN) {
                const ssize_t n = ::read(master, buffer, std::min(sizeof buffer, room));
                if (n > 0) {
                    std::lock_guard<std::mutex> lock(mutex);
                    bytes.insert(bytes.end(), buffer, buffer + n);
                    continue;
                }
                if (n < 0 && (errno == EAGAIN || errno == EINTR)) continue;
            }
            if (fds[0].revents & (POLLHUP | POLLERR | POLLNVAL)) break;
        }
        std::lock_guard<std::mutex> lock(mutex);
        failed = true;
    }
};

PseudoTerminal::~PseudoTerminal()
{
    if (reader_) {
        const uint64_t one = 1;
        [[maybe_unused]] const ssize_t n = ::write(reader_->stop_fd, &one, sizeof one);
        reader_->thread.join();
        ::close(reader_->stop_fd);
    }
    if (!link_path_.empty()) ::unlink(link_path_.c_str());
    if (slave_ >= 0) ::close(slave_);
    if (master_ >= 0) ::close(master_);
}

void PseudoTerminal::read_on_own_thread(Realtime mode, int priority)
{
    if (reader_) throw Error(slave_path_ + ": read_on_own_thread called a second time");
    auto reader = std::make_unique<Reader>();
    reader->stop_fd = ::eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
    if (reader->stop_fd < 0) throw Error(slave_path_ + ": cannot create an eventfd (" + std::strerror(errno) + ")");
    reader->thread = std::thread([r = reader.get(), master = master_, mode, priority] { r->run(master, mode, priority); });
    reader_ = std::move(reader);
}

long PseudoTerminal::read_available(uint8_t* data, size_t size)
{
    if (reader_) {
        std::lock_guard<std::mutex> lock(reader_->mutex);
        const size_t n = std::min(size, reader_->bytes.size());
        if (n == 0 && reader_->failed) return -1;
        std::copy_n(reader_->bytes.begin(), n, data);
        reader_->bytes.erase(reader_->bytes.begin(), reader_->bytes.begin() + long(n));
        return long(n);
    }
    ssize_t n = ::read(master_, data, size);
    if (n < 0) return (errno == EAGAIN || errno == EINTR) ? 0 : -1;
    return n;
}

bool PseudoTerminal::write_frame(const uint8_t* data, size_t size)
{
    ssize_t n = ::write(master_, data, size);
    return n == ssize_t(size);
}

}  // namespace cpm::vehicle
