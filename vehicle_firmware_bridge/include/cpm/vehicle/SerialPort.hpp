#pragma once
#include <cstddef>
#include <cstdint>
#include <cpm/Error.hpp>
#include <cpm/Realtime.hpp>

#include <memory>
#include <string>

namespace cpm::vehicle {

/// The serial device cannot be used now, but may be later: not there (not plugged in, the
/// simulator not started) or held by another program.
class DeviceUnavailable : public Error
{
public:
    using Error::Error;
};

/// A serial line in raw mode (termios: 8N1, no echo, no line editing, no flow control), or a
/// pseudo-terminal's slave side, which behaves the same. Owns its file descriptor.
class SerialPort
{
public:
    /// Opens `path` at `baud` (one of the standard rates; ignored by a pty) and discards what
    /// was waiting in the input. Takes an exclusive flock on the device, so two bridges never
    /// share one line. Throws DeviceUnavailable when there is no such device or another
    /// program holds it, else cpm::Error naming the path and the reason (not a terminal, no
    /// permission, bad baud).
    SerialPort(const std::string& path, int baud);
    ~SerialPort();
    SerialPort(const SerialPort&) = delete;
    SerialPort& operator=(const SerialPort&) = delete;

    /// Waits up to timeout_ms for bytes and reads what is there (at most `size`). Returns the
    /// count, 0 on timeout, -1 when the line is gone (hang-up, device removed).
    long read_some(uint8_t* data, size_t size, int timeout_ms);
    /// Writes all bytes (waits briefly when the line is full); false when the line is gone.
    bool write_all(const uint8_t* data, size_t size);
    /// Drops what was written but not yet sent (tcflush TCOFLUSH: a serial driver's queue; on a
    /// pty, what the other end has not taken into its line buffer); false when that failed.
    bool discard_output();

    /// Throws cpm::Error naming the rate when `baud` is not one SerialPort can set.
    static void check_baud(int baud, const std::string& path);

    int fd() const { return fd_; }
    /// True when the device is a pseudo-terminal (a simulated car), not real hardware.
    bool is_pseudo_terminal() const { return pty_; }

private:
    int fd_ = -1;
    bool pty_ = false;
};

/// A pseudo-terminal pair as firmware_sim uses it: the simulator holds the master side; the
/// slave (device_path()) is set to raw mode at once so nothing is echoed or line-buffered.
/// With a link path, a symlink there points to the slave (removed again on destruction).
class PseudoTerminal
{
public:
    explicit PseudoTerminal(const std::string& link_path = {});
    ~PseudoTerminal();
    PseudoTerminal(const PseudoTerminal&) = delete;
    PseudoTerminal& operator=(const PseudoTerminal&) = delete;

    int master_fd() const { return master_; }
    const std::string& device_path() const { return slave_path_; }
    /// Reads what the host wrote, without waiting; -1 on error.
    long read_available(uint8_t* data, size_t size);
    /// From now on a thread of its own (SCHED_FIFO at `priority` when `mode` asks for real time)
    /// reads what the host writes, and read_available() takes it from there without a system
    /// call on the line. A read or poll of a pty waits while the kernel's worker hands written
    /// bytes over, a kworker of normal priority: a real-time loop reading the line itself missed
    /// 431 of its 4 ms ticks in 24 s beside a busy machine (reads of up to 59 ms; measured).
    /// Holds at most 64 KiB, then leaves the rest in the line (the host sees it full, as a real
    /// line's). Call at most once; the thread ends with the PseudoTerminal.
    void read_on_own_thread(Realtime mode = Realtime::off, int priority = realtime_priority::line_reader);
    /// Writes a frame; drops it (returns false) when no host reads and the buffer is full.
    bool write_frame(const uint8_t* data, size_t size);

private:
    struct Reader;
    int master_ = -1;
    int slave_ = -1;  // held open so the master never sees a hang-up while the host reconnects
    std::string slave_path_;
    std::string link_path_;
    std::unique_ptr<Reader> reader_;  ///< with read_on_own_thread
};

}  // namespace cpm::vehicle
