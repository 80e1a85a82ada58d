#pragma once
// What the history e2e tests share: the writer process's data times, a participant on UDP
// loopback, the wait for the service to hold an object's samples.
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>

#include <cpm_test/Dds.hpp>
#include <cpm_test/Isolation.hpp>

#include <chrono>
#include <string>

constexpr uint64_t kBase = 1'700'000'000'000'000'000ull;  // history_writer's first data time; then 1 ms apart
constexpr uint64_t kMs = 1'000'000;

/// UDP loopback only: every test starts a new cpm_history, which reuses the previous one's
/// shared-memory port, and Fast DDS 2.9 in a long-lived process keeps sending to the old port.
inline cpm::ParticipantOptions udp_only()
{
    auto o = cpm_test::isolated_options();
    o.shared_memory = false;
    return o;
}

/// True once the service holds at least n samples of topic/key (polls `latest`).
inline bool wait_for_samples(cpm::HistoryClient& client, const std::string& topic, const std::string& key, uint64_t n,
                             std::chrono::milliseconds timeout = std::chrono::seconds(30))
{
    return cpm_test::wait_until([&] {
        try {
            auto r = client.latest(topic, key);
            return !r.objects().empty() && r.objects()[0].samples_held() >= n;
        } catch (const std::exception&) {
            return false;
        }
    }, timeout, std::chrono::milliseconds(20));
}
