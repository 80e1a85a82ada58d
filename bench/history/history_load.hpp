#pragma once
// The history benchmarks' load: VehicleState of 100 vehicles at a given rate, and what the
// service committed of it.
#include <cpm/HistoryClient.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Writer.hpp>
#include <cpm/get_time_ns.hpp>
#include <cpm/stamp_message.hpp>

#include <VehicleState.h>

#include <chrono>
#include <thread>

namespace bench {

/// The history benchmarks' participants: on `domain`, shared memory or UDP loopback only.
inline cpm::ParticipantOptions history_bench_options(int domain, bool shm, const std::string& name)
{
    cpm::ParticipantOptions o;
    o.domain_id = domain;
    o.name = name;
    o.shared_memory = shm;
    return o;
}

/// The load's writer, reliable with a depth of 100 per vehicle, like a car's.
inline cpm::Writer<VehicleState> vehicle_state_writer(cpm::Participant& p)
{
    cpm::WriterOptions wo;
    wo.reliable = true;
    wo.history_depth = 100;
    return cpm::Writer<VehicleState>(p, "vehicleState", wo);
}

/// Writes `rate` samples/s spread over 100 vehicles for `seconds`; returns the number written.
inline uint64_t write_at(cpm::Writer<VehicleState>& w, double rate, double seconds, double& tag)
{
    const auto start = std::chrono::steady_clock::now();
    uint64_t written = 0;
    VehicleState s;
    while (true) {
        const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        if (elapsed >= seconds) break;
        const uint64_t due = uint64_t(elapsed * rate);
        for (; written < due; ++written) {
            s.vehicle_id(uint8_t(written % 100));
            cpm::stamp_message(s, cpm::get_time_ns(), 0);
            s.pose().x(tag++);
            (void)w.write(s);
        }
        std::this_thread::sleep_for(std::chrono::microseconds(200));
    }
    return written;
}

/// What the service committed on vehicleState so far (all vehicles).
inline uint64_t committed(cpm::HistoryClient& client)
{
    HistoryRequest rq = cpm::HistoryClient::make(cpm::history::Kind::search, "", "");
    rq.name_regex("^vehicleState/");
    uint64_t total = 0;
    const HistoryReply reply = client.request(rq);  // a named reply: a temporary would die before the loop
    for (const auto& o : reply.objects()) total += o.samples_total();
    return total;
}

}  // namespace bench
