#include <cpm/vehicle/SerialPort.hpp>

#include <gtest/gtest.h>

#include <fcntl.h>
#include <termios.h>
#include <unistd.h>

#include <string>

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
