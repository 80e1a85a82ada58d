#pragma once
// The payload bytes of one object in the store (Store.cpp): first in first out, never moved.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <deque>
#include <memory>

namespace cpm::rtdb::detail {

/// Payload bytes of one object, first in first out, in chunks of 16 KiB (a larger sample gets
/// a chunk of its own). A sample never spans chunks and never moves; a chunk is freed when its
/// last sample is evicted. Unlike one growing buffer, this keeps at most one partly used chunk
/// beyond the payload held. Not thread-safe: the store's object lock guards it.
class ByteChunks
{
public:
    static constexpr size_t kChunk = 16 * 1024;
    /// Stores the bytes of the sample with sequence number seq; returns where they stay until popped.
    const uint8_t* push(const uint8_t* data, size_t size, uint64_t seq)
    {
        if (chunks_.empty() || chunks_.back().capacity - chunks_.back().used < size) {
            // An emptied only chunk too small for this sample goes, so the front always holds the oldest.
            if (!chunks_.empty() && chunks_.back().samples == 0) chunks_.pop_back();
            const size_t cap = std::max(kChunk, size);
            chunks_.push_back({std::unique_ptr<uint8_t[]>(new uint8_t[cap]), cap, 0, 0, 0, 0, 0});
        }
        Chunk& c = chunks_.back();
        if (c.used == 0) {  // a new chunk, or the only one, emptied and begun again
            c.first_seq = seq;
            c.pushed = 0;
            c.stride = size;
        }
        uint8_t* where = c.data.get() + c.used;
        std::memcpy(where, data, size);
        if (size != c.stride) c.stride = 0;
        c.used += size;
        ++c.samples;
        ++c.pushed;
        return where;
    }
    /// Starts fetching the payload of sample seq into the cache, found without its record: while
    /// samples are all of one size, chunks hold equally many and a sample's place follows from
    /// its number (otherwise nothing is fetched). A copying query does this while it still
    /// searches for the record, so that the two cache misses overlap instead of following each
    /// other. It loads the bytes: a prefetch instruction made no difference on this machine
    /// (bench_history_store, side by side), plain loads do.
    void fetch(uint64_t seq) const
    {
        if (chunks_.empty()) return;
        const Chunk& front = chunks_.front();
        if (seq < front.first_seq || front.pushed == 0) return;
        const uint64_t k = (seq - front.first_seq) / front.pushed;
        if (k >= chunks_.size()) return;
        const Chunk& c = chunks_[k];
        if (c.stride == 0 || seq < c.first_seq || seq - c.first_seq >= c.pushed) return;
        const uint8_t* p = c.data.get() + (seq - c.first_seq) * c.stride;
        uint8_t any = 0;
        for (size_t line = 0; line < c.stride; line += 64) any ^= static_cast<const volatile uint8_t*>(p)[line];
        any ^= static_cast<const volatile uint8_t*>(p)[c.stride - 1];
        asm volatile("" : : "r"(any));  // the bytes are wanted in the cache, not their value
    }
    /// The oldest sample is evicted. Samples leave in the order they came, so it lies in the
    /// front chunk.
    void pop()
    {
        Chunk& c = chunks_.front();
        if (--c.samples > 0) return;
        if (chunks_.size() > 1) chunks_.pop_front();
        else c.used = 0;  // the only chunk, empty: start again at its beginning
    }
    /// Chunks allocated: the memory held is about chunks() × kChunk (larger samples: their size).
    size_t chunks() const { return chunks_.size(); }

private:
    struct Chunk
    {
        std::unique_ptr<uint8_t[]> data;
        size_t capacity, used;
        size_t samples;      ///< not yet evicted
        uint64_t first_seq;  ///< of the first sample pushed into it
        size_t pushed;       ///< samples pushed into it
        size_t stride;       ///< their size while all are of one size, else 0
    };
    std::deque<Chunk> chunks_;
};

}  // namespace cpm::rtdb::detail
