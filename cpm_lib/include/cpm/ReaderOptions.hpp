#pragma once
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>

namespace cpm {

/// Quality of service and buffering of the reader family.
struct ReaderOptions
{
    bool reliable = false;         ///< request reliable delivery (needs a reliable writer)
    bool keep_all = false;         ///< DDS keeps every sample until taken (else history_depth per instance)
    int history_depth = 1;         ///< DDS samples kept per instance when not keep_all
    bool transient_local = false;  ///< receive samples written before the reader existed
    size_t buffer_capacity = 2000; ///< Reader/MultiVehicleReader: samples buffered per vehicle; oldest arrivals go first
    std::optional<uint8_t> vehicle_id;  ///< Reader of a keyed type: only this vehicle's samples
    bool data_sharing = false;     ///< Fast DDS data sharing (see WriterOptions::data_sharing)
    /// A reliable reader answers a writer's heartbeat (acknowledging what it has, asking for
    /// what it lacks) this long after it: heartbeats within that time get one answer. 0 (the
    /// default) answers at once, which a keep-all writer whose window is full waits for. A
    /// reader of a keep-last writer that writes often may wait: Fast DDS sends a heartbeat with
    /// every sample of a writer of depth 1, and each answer wakes a thread on both sides (the
    /// lab clock's topics). A sample lost on the way is asked for again only after this wait.
    std::chrono::milliseconds acknowledge_after{0};
    /// AsyncReader only: run the callback on the DDS receive thread that delivered the
    /// samples, instead of the reader's own thread. Saves a thread hop (the latency of a raw
    /// Fast DDS listener), for callbacks that are short and never block: while it runs, this
    /// reader receives nothing and other readers sharing that DDS thread wait too. Writing
    /// with a cpm::Writer from it is fine; waiting for anything (a lock held long, a reply,
    /// sleep, a reliable writer's full window) stalls DDS. Never destroy the reader from
    /// inside its callback (stop() is fine). A writer in the same process delivers on its own
    /// thread, inside its write(). Other readers refuse the option.
    bool dds_thread_callback = false;

    /// These options with dds_thread_callback set (a topic's reader options, for an AsyncReader
    /// whose callback runs on the DDS thread).
    constexpr ReaderOptions on_dds_thread() const
    {
        ReaderOptions o = *this;
        o.dds_thread_callback = true;
        return o;
    }
};

}  // namespace cpm
