#pragma once
// What DDS discovery tells a participant of the others: participants, writers and readers as they
// come, change and go, in cpm's own words (ParticipantOptions::on_discovery).
#include <array>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

namespace cpm {

/// A participant, writer or reader found, changed or gone.
struct DiscoveryEvent
{
    enum class Kind {
        participant_found,
        participant_gone,  ///< it left, or its lease ran out
        writer_found,
        writer_changed,  ///< its QoS changed
        writer_gone,
        reader_found,
        reader_changed,
        reader_gone,
    };
    Kind kind = Kind::participant_found;
    /// The DDS GUID: 12 bytes of the participant's prefix, then 4 of the entity (a participant's
    /// own entity is 0.0.1.c1). A writer's or reader's prefix is its participant's.
    std::array<uint8_t, 16> guid{};
    std::string participant_name;             ///< participants only
    std::vector<std::string> unicast_locators;    ///< participants only: "UDPv4:[127.0.0.1]:7411", "SHM:[…]:…"
    std::vector<std::string> multicast_locators;  ///< participants only
    std::string topic, type_name;             ///< writers and readers only
    bool keyed = false, reliable = false, transient_local = false;  ///< writers and readers only

    bool is_participant() const { return kind == Kind::participant_found || kind == Kind::participant_gone; }
    /// The 12-byte participant prefix of the GUID, as the participant's own key.
    std::array<uint8_t, 12> prefix() const
    {
        std::array<uint8_t, 12> p{};
        for (size_t i = 0; i < p.size(); ++i) p[i] = guid[i];
        return p;
    }
};

/// Called on Fast DDS's discovery thread, for every event from the participant's first moment:
/// return quickly, and create no DDS entity in it (hand the work to a thread of your own).
using DiscoveryCallback = std::function<void(const DiscoveryEvent&)>;

}  // namespace cpm
