#pragma once
// A process-wide service's DDS entities that live until the process exits and are destroyed
// then, once no call uses them. The log and the parameter cache are never destroyed themselves
// (a message may be written until the very end), but readers and writers they hold keep the
// default participant alive: Fast DDS then never deletes it and never unlinks its shared memory,
// 4 MB of RAM-backed /dev/shm left by every process that ended.
#include <atomic>
#include <chrono>
#include <cstdlib>
#include <memory>
#include <thread>

namespace cpm::detail {

template <class T>
class UntilExit
{
public:
    /// A scoped use of the object: nullptr before it is set and after the process began to exit.
    class Use
    {
    public:
        explicit Use(UntilExit& owner) : owner_(owner)
        {
            owner_.users_.fetch_add(1);  // seq_cst, as below: each side must see the other's write
            object_ = owner_.object_.load();
        }
        ~Use() { owner_.users_.fetch_sub(1, std::memory_order_acq_rel); }
        Use(const Use&) = delete;
        Use& operator=(const Use&) = delete;
        T* get() const { return object_; }
        T* operator->() const { return object_; }
        explicit operator bool() const { return object_ != nullptr; }

    private:
        UntilExit& owner_;
        T* object_ = nullptr;
    };

    /// Takes `object`, to be destroyed at exit. Call once, after the default participant exists
    /// (it is destroyed after what is registered later); `this` must live until exit.
    void set(std::unique_ptr<T> object)
    {
        object_.store(object.release(), std::memory_order_release);
        static UntilExit* self = this;  // one instance per T in this process
        std::atexit([] { self->close(); });
    }
    Use use() { return Use(*this); }
    bool is_set() const { return object_.load(std::memory_order_acquire) != nullptr; }
    bool closed() const { return closed_.load(std::memory_order_acquire); }

private:
    void close()
    {
        closed_.store(true, std::memory_order_release);
        T* object = object_.exchange(nullptr);
        // A call that took the object before the exchange finishes first (a write takes
        // microseconds); a thread stuck in one for a second is left the object, leaked.
        const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(1);
        while (users_.load() > 0) {
            if (std::chrono::steady_clock::now() > deadline) return;
            std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
        delete object;
    }

    std::atomic<T*> object_{nullptr};
    std::atomic<int> users_{0};
    std::atomic<bool> closed_{false};
};

}  // namespace cpm::detail
