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
    /// Fast DDS data sharing between processes on this host (needs it on the reader too).
    /// Off by default: measured slower for small samples (bench/latency); try it for
    /// large ones such as camera frames.
    bool data_sharing = false;
};

}  // namespace cpm
