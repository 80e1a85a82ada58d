#pragma once

namespace cpm {

/// Quality of service of a Writer. A reader only matches a writer that offers at least
/// what it requests (a reliable reader needs a reliable writer, transient-local likewise).
struct WriterOptions
{
    bool reliable = false;         ///< retransmit lost samples (else best effort)
    bool keep_all = false;         ///< keep every unacknowledged sample (else the last history_depth)
    int history_depth = 1;         ///< samples kept per instance when not keep_all
    bool transient_local = false;  ///< late-joining readers receive the kept samples
    /// With keep_all: samples per instance (vehicle) kept until every reader acknowledged them.
    /// When that many are unacknowledged, write() waits up to 100 ms, then returns false.
    /// Bounds memory (a keep-all writer serves up to 256 instances); 1024 measured fastest
    /// on this machine (bench/throughput): an unbounded Fast DDS writer gets slower the more
    /// it holds, and a window larger than the shared-memory queue loses samples to repairs.
    int max_unacknowledged = 1024;
    /// Fast DDS data sharing between processes on this host (needs it on the reader too): the
    /// writer serializes into a pool in shared memory that readers read from. For large samples
    /// (bench/large: 1 MiB one way 0.18x Cyclone DDS's time, 2.4x faster than the shared-memory
    /// transport); off by default, slower for small ones (bench/latency). Needs a bounded,
    /// unkeyed type and no DDS Security (else refused, naming why); the pool holds twice the
    /// history (history_depth, or max_unacknowledged with keep_all) and is limited to 512 MiB.
    /// With a plain type aligned to at most 4 bytes (Writer::shares_in_place()),
    /// write_in_place() and ReaderAbstract::take_each() copy nothing at all.
    /// The samples live in the writer's pool: what a reader has not taken when the writer is
    /// destroyed is lost, so wait_for_acknowledgments() before a writer goes.
    bool data_sharing = false;
};

}  // namespace cpm
