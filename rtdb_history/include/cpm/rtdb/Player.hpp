#pragma once
// Replays a recording: publishes its samples again, on their topics under their type names,
// with their payloads (stamps included) as recorded, in the order they were committed and with
// their original spacing scaled by the rate. Types cpm does not know are replayed as raw bytes
// too. fsm_node, cpm monitor or another cpm_history --record see a recorded drive as it was.
#include <cpm/Participant.hpp>

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace cpm::rtdb {

/// The topics a replay leaves out unless named in PlayOptions::include (names and fnmatch
/// patterns, the rows of cpm/nodes.hpp that steer the lab): the history service's own requests
/// and replies, and the lab's control plane (a replayed stop trigger or ready status would steer
/// the live lab's timers; a replayed parameter request would be answered).
const std::vector<std::string>& control_topics();

struct PlayOptions
{
    double rate = 1.0;                      ///< 2: twice as fast; must be > 0
    uint64_t from_ns = 0;                   ///< commit times [from, to]
    uint64_t to_ns = UINT64_MAX;
    std::vector<std::string> include;       ///< topic regexes (full match); empty: every topic but control_topics()
    std::vector<std::string> exclude;       ///< topic regexes never replayed
    /// How long to wait for each replayed topic to have a reader before the first sample.
    uint64_t wait_for_readers_ns = 3'000'000'000ull;
};

struct PlayStats
{
    uint64_t published = 0, failed = 0;
    std::vector<std::string> topics;           ///< replayed
    std::vector<std::string> topics_unread;    ///< replayed with no reader matched in time
    uint64_t first_commit_ns = 0, last_commit_ns = 0;
    /// How late each sample left against its scaled original spacing, in ns.
    double late_p50_ns = 0, late_p99_ns = 0, late_max_ns = 0;
};

class Player
{
public:
    /// Opens the recording (throws cpm::Error naming the file when it is not one) and
    /// makes a writer per topic it will replay (throws cpm::Error when DDS refuses one).
    Player(Participant& participant, const std::string& path, PlayOptions options);
    ~Player();
    Player(const Player&) = delete;
    Player& operator=(const Player&) = delete;

    /// The topics the options select, with their type names.
    const std::vector<std::pair<std::string, std::string>>& topics() const;
    /// Publishes until the end (or `stop` returns true), then waits for the readers to
    /// acknowledge what was sent.
    PlayStats run(const std::function<bool()>& stop = [] { return false; });

private:
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::rtdb
