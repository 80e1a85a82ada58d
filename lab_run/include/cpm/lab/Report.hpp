#pragma once
// A run drawn for people: from a run's folder (recording.db, summary.json) the figures of the
// run as numbers and as plots made with gnuplot (PNG files beside report.html):
// - each car's true path on the map (walls, markers, gates, lanes),
// - speed and steering over time, the state machines' states over time,
// - clearance to the nearest wall, the smallest distance between two cars,
// - per-topic rates and delay (create -> commit), the run's warnings and errors.
// The figures go into summary.json under "report" too.
#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace cpm::lab {

struct Report
{
    std::string html;                 ///< report.html's path
    std::vector<std::string> images;  ///< the plots' paths
    nlohmann::json figures;           ///< what summary.json's "report" holds
};

/// Draws the report of the run in `run_dir`. Throws cpm::Error naming what is missing (the
/// folder, its recording, gnuplot), why the recording cannot be read, or what failed (gnuplot's
/// own message).
Report make_report(const std::string& run_dir);

}  // namespace cpm::lab
