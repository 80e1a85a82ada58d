// cpm vehicle sim: one simulated car (firmware_sim + vehicle_bridge joined by a pty) or several.
#include "Command.hpp"

#include <cpm/CommandLine.hpp>
#include <cpm/vehicle/VehicleModel.hpp>

#include <atomic>
#include <cerrno>
#include <chrono>
#include <climits>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <cstring>
#include <string>
#include <thread>
#include <sys/prctl.h>
#include <unistd.h>
#include <sys/wait.h>
#include <vector>

namespace {

std::string program_dir()
{
    char path[PATH_MAX];
    ssize_t n = readlink("/proc/self/exe", path, sizeof path - 1);
    if (n <= 0) return ".";
    std::string exe(path, size_t(n));
    return exe.substr(0, exe.rfind('/'));
}

/// A child process; its stdout comes back through a pipe when `capture` is set.
struct Child
{
    pid_t pid = -1;
    int out = -1;
    std::string name;
};

Child spawn(const std::string& name, const std::vector<std::string>& argv, bool capture)
{
    int fds[2] = {-1, -1};
    if (capture && pipe(fds) != 0) throw cpm::Error("cannot create a pipe for " + name);
    pid_t pid = fork();
    if (pid < 0) throw cpm::Error("cannot start " + name + " (" + std::strerror(errno) + ")");
    if (pid == 0) {
        prctl(PR_SET_PDEATHSIG, SIGTERM);  // never outlive this launcher, even if it is killed
        if (capture) {
            dup2(fds[1], STDOUT_FILENO);
            close(fds[0]);
            close(fds[1]);
        }
        // Nothing of ours leaks into the child (Fast DDS's shared-memory lock files included,
        // which would make its ports look held by the wrong process).
        close_range(3, ~0u, 0);
        std::vector<char*> args;
        for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
        args.push_back(nullptr);
        execv(args[0], args.data());
        std::fprintf(stderr, "cpm vehicle sim: cannot run %s (%s)\n", args[0], std::strerror(errno));
        _exit(127);
    }
    if (capture) close(fds[1]);
    return {pid, capture ? fds[0] : -1, name};
}

/// Reads one line from fd (blocking); empty at end of file.
std::string read_line(int fd)
{
    std::string line;
    char c;
    while (read(fd, &c, 1) == 1) {
        if (c == '\n') return line;
        line += c;
    }
    return line;
}

const char* const kVehicleSimHelp =
    "usage: cpm vehicle sim --id N [--count K] [--map FILE] [--start X,Y,YAW] [--spacing M]\n"
    "                       [--params FILE] [--calibration FILE] [--dds_domain N]\n"
    "\n"
    "Starts simulated car N: firmware_sim (vehicle model, sensors, watchdog) and vehicle_bridge,\n"
    "joined by a pseudo-terminal exactly as a real car's computer and microcontroller are by a\n"
    "serial line. The car publishes vehicleState, rangeSensors and vehicleObservation and obeys\n"
    "vehicleCommand* for its id. With --count K, cars N .. N+K-1 share one world, each --spacing\n"
    "metres (default 0.6) behind the previous one along the start heading; their rangers see\n"
    "each other. Runs until Ctrl-C, then prints each process's statistics (JSON lines).\n";

int vehicle_sim(const std::vector<std::string>& args)
{
    auto parsed = cpm::cli::parse_args(args,
                                       {{"--id", true}, {"--count", true}, {"--map", true}, {"--start", true},
                                        {"--spacing", true}, {"--params", true}, {"--calibration", true}},
                                       "cpm vehicle sim");
    if (!parsed.positional.empty()) throw cpm::cli::UsageError("cpm vehicle sim: unexpected argument '" + parsed.positional[0] + "'");
    if (!parsed.has("--id")) throw cpm::cli::UsageError("cpm vehicle sim: --id is required (the vehicle id, 1..255)");
    long long first = cpm::cli::parse_integer("--id", parsed.get("--id"), 1, 255);
    long long count = cpm::cli::parse_integer("--count", parsed.get("--count", "1"), 1, 256 - first);
    double spacing = cpm::cli::parse_number("--spacing", parsed.get("--spacing", "0.6"), 0, 100);
    auto start = cpm::vehicle::parse_pose("--start", parsed.get("--start", "0,0,0"));
    double x0 = start.x, y0 = start.y, yaw = start.yaw;

    const std::string dir = program_dir();
    std::vector<Child> children;
    auto stop_all = [&] {
        for (auto& c : children) kill(c.pid, SIGTERM);
    };
    cpm::cli::stop_on_signals();
    std::vector<std::thread> copiers;
    try {
        for (long long k = 0; k < count; ++k) {
            std::string id = std::to_string(first + k);
            char pose[96];
            std::snprintf(pose, sizeof pose, "%.6f,%.6f,%.6f", x0 - k * spacing * std::cos(yaw), y0 - k * spacing * std::sin(yaw), yaw);
            std::vector<std::string> sim_argv{dir + "/firmware_sim", "--vehicle_id", id, "--start", pose};
            for (const char* flag : {"--map", "--params"}) {
                if (parsed.has(flag)) sim_argv.insert(sim_argv.end(), {flag, parsed.get(flag)});
            }
            sim_argv.insert(sim_argv.end(), parsed.init_args.begin(), parsed.init_args.end());
            children.push_back(spawn("firmware_sim " + id, sim_argv, true));
            std::string line = read_line(children.back().out);
            if (line.rfind("device: ", 0) != 0) throw cpm::Error("firmware_sim " + id + " did not start (see its error above)");
            std::string device = line.substr(8);

            std::vector<std::string> bridge_argv{dir + "/vehicle_bridge", "--vehicle_id", id, "--device", device, "--start", pose};
            if (parsed.has("--calibration")) bridge_argv.insert(bridge_argv.end(), {"--calibration", parsed.get("--calibration")});
            bridge_argv.insert(bridge_argv.end(), parsed.init_args.begin(), parsed.init_args.end());
            children.push_back(spawn("vehicle_bridge " + id, bridge_argv, false));
            std::printf("vehicle %s: firmware_sim pid %d on %s, vehicle_bridge pid %d, start %s\n", id.c_str(),
                        int(children[children.size() - 2].pid), device.c_str(), int(children.back().pid), pose);
            std::fflush(stdout);
            int fd = children[children.size() - 2].out;
            copiers.emplace_back([fd] {
                for (std::string l = read_line(fd); !l.empty(); l = read_line(fd)) {
                    std::printf("%s\n", l.c_str());
                    std::fflush(stdout);
                }
            });
        }
    } catch (...) {
        stop_all();
        for (auto& c : children) waitpid(c.pid, nullptr, 0);
        for (auto& t : copiers) t.join();
        throw;
    }

    int exit_code = 0;
    while (!cpm::cli::stop_requested()) {
        int status = 0;
        pid_t pid = waitpid(-1, &status, WNOHANG);
        if (pid > 0) {
            for (auto& c : children) {
                if (c.pid != pid) continue;
                std::fprintf(stderr, "cpm vehicle sim: %s exited (%s %d); stopping the others\n", c.name.c_str(),
                             WIFSIGNALED(status) ? "signal" : "code", WIFSIGNALED(status) ? WTERMSIG(status) : WEXITSTATUS(status));
                c.pid = -1;
            }
            exit_code = 1;
            break;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    // Bridges first, so that none of them reports its simulator's end as a lost link.
    for (int pass = 0; pass < 2; ++pass) {
        for (auto& c : children) {
            bool bridge = c.name.rfind("vehicle_bridge", 0) == 0;
            if (c.pid > 0 && bridge == (pass == 0)) kill(c.pid, SIGTERM);
        }
        for (auto& c : children) {
            bool bridge = c.name.rfind("vehicle_bridge", 0) == 0;
            if (c.pid > 0 && bridge == (pass == 0)) waitpid(c.pid, nullptr, 0);
        }
    }
    for (auto& t : copiers) t.join();
    return exit_code;
}

}  // namespace

namespace cpm::tools {

std::vector<Command> vehicle_commands()
{
    return {{"vehicle", "sim", "start simulated cars: firmware simulator + vehicle bridge over a pty", kVehicleSimHelp,
             vehicle_sim}};
}

}  // namespace cpm::tools
