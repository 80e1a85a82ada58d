#include <cpm/vehicle/SerialPort.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <thread>

using namespace cpm::vehicle;

namespace {

speed_t line_speed(const std::string& path)
{
    const int fd = ::open(path.c_str(), O_RDWR | O_NOCTTY | O_NONBLOCK | O_CLOEXEC);
    EXPECT_GE(fd, 0) << path;
    termios tio{};
    EXPECT_EQ(tcgetattr(fd, &tio), 0);
    ::close(fd);
    return cfgetospeed(&tio);
}

}  // namespace

// A second program refused the line must leave it as the first one set it: the same speed, and
// the bytes waiting for the first one still there.
TEST(SerialPort, ASecondOpenIsRefusedBeforeItTouchesTheLine)
{
    PseudoTerminal pty;
    SerialPort first(pty.device_path(), 115200);
    ASSERT_EQ(line_speed(pty.device_path()), B115200);
    const uint8_t waiting[] = {'c', 'a', 'r'};
    ASSERT_TRUE(pty.write_frame(waiting, sizeof waiting));

    try {
        SerialPort second(pty.device_path(), 9600);
        FAIL() << "a second SerialPort opened a line in use";
    } catch (const DeviceUnavailable& e) {
        EXPECT_NE(std::string(e.what()).find("in use by another program"), std::string::npos) << e.what();
    }

    EXPECT_EQ(line_speed(pty.device_path()), B115200) << "the refused program changed the line's speed";
    uint8_t got[8] = {};
    ASSERT_EQ(first.read_some(got, sizeof got, 1000), 3);
    EXPECT_EQ(std::string(got, got + 3), "car");
}

TEST(SerialPort, TheLineIsFreeAgainOnceTheFirstHasClosedIt)
{
    PseudoTerminal pty;
    { SerialPort first(pty.device_path(), 115200); }
    SerialPort second(pty.device_path(), 9600);
    EXPECT_EQ(line_speed(pty.device_path()), B9600);
    EXPECT_TRUE(second.is_pseudo_terminal());
}

// Read on a thread of its own, the line still hands over every byte in order, also more than
// the reader holds at once (64 KiB) while the loop takes them in small bites.
TEST(PseudoTerminal, ReadOnItsOwnThreadEveryByteArrivesInOrder)
{
    PseudoTerminal pty;
    pty.read_on_own_thread();
    const int host = ::open(pty.device_path().c_str(), O_WRONLY | O_NOCTTY | O_CLOEXEC);  // blocking: waits while the line is full
    ASSERT_GE(host, 0);
    constexpr size_t kTotal = 200 * 1024;
    std::thread writer([&] {
        uint8_t chunk[1000];
        for (size_t sent = 0; sent < kTotal;) {
            for (size_t k = 0; k < sizeof chunk; ++k) chunk[k] = uint8_t((sent + k) % 251);
            const ssize_t n = ::write(host, chunk, std::min(sizeof chunk, kTotal - sent));
            if (n <= 0) return;
            sent += size_t(n);
        }
    });
    std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the reader fills up, then the line
    size_t got = 0;
    bool in_order = true;
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (got < kTotal && std::chrono::steady_clock::now() < deadline) {
        uint8_t bite[100];
        const long n = pty.read_available(bite, sizeof bite);
        ASSERT_GE(n, 0);
        for (long k = 0; k < n; ++k) in_order = in_order && bite[k] == uint8_t((got + size_t(k)) % 251);
        got += size_t(n);
        if (n == 0) std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    writer.join();
    ::close(host);
    EXPECT_EQ(got, kTotal);
    EXPECT_TRUE(in_order);
}
