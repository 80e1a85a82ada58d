#pragma once
// What both fault suites read off a running lab: the source tree, and the firmware simulator's
// motor trace (--trace-pwm).
#include <cpm_test/Process.hpp>
#include <cpm_test/SourceDir.hpp>

#include <cstdint>
#include <sstream>
#include <string>
#include <utility>
#include <vector>

namespace cpm_faults {

inline const std::string kRoot = cpm_test::source_dir();

/// The firmware simulator's `pwm T MODE PWM` trace after time t: (time, mode); mode 0 brake,
/// 1 forward, 2 reverse.
inline std::vector<std::pair<uint64_t, int>> pwm_after(const std::string& sim_output, uint64_t t)
{
    std::vector<std::pair<uint64_t, int>> out;
    std::istringstream in(sim_output);
    for (std::string word; in >> word;) {
        if (word != "pwm") continue;
        unsigned long long time = 0;
        int mode = 0, pwm = 0;
        in >> time >> mode >> pwm;
        if (time > t) out.emplace_back(time, mode);
    }
    return out;
}

/// The first time after t the motor was in `mode`, or 0.
inline uint64_t first_mode_after(const std::string& sim_output, uint64_t t, int mode)
{
    for (const auto& [time, m] : pwm_after(sim_output, t))
        if (m == mode) return time;
    return 0;
}
inline std::vector<std::pair<uint64_t, int>> pwm_after(const cpm_test::Process& sim, uint64_t t) { return pwm_after(sim.output(), t); }
inline uint64_t first_mode_after(const cpm_test::Process& sim, uint64_t t, int mode) { return first_mode_after(sim.output(), t, mode); }

}  // namespace cpm_faults
