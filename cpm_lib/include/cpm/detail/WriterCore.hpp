#pragma once
#include <chrono>
#include <cstddef>
#include <memory>
#include <string>

#include <cpm/WriterOptions.hpp>
#include <cpm/detail/TypeSupport.hpp>

namespace cpm::detail {
class ParticipantCore;

/// The type-independent part of Writer<T>: one DDS DataWriter and its match count.
class WriterCore
{
public:
    /// Throws cpm::Error naming the topic when the writer cannot be created.
    WriterCore(std::shared_ptr<ParticipantCore> participant, const std::string& topic,
               MakeTypeSupport make_type, const WriterOptions& options);
    ~WriterCore();
    WriterCore(const WriterCore&) = delete;
    WriterCore& operator=(const WriterCore&) = delete;
    /// The DDS writer moves along; the moved-from core may only be destroyed or assigned to.
    WriterCore(WriterCore&& other) noexcept;
    WriterCore& operator=(WriterCore&& other) noexcept;

    /// Publishes one sample; false when DDS refused it (e.g. keep-all history full). Never throws.
    bool write(const void* sample);
    /// A sample DDS lends to be filled in place (not initialised: it holds an earlier sample's
    /// bytes), or nullptr when it
    /// cannot lend one (a type that is not plain, or every loanable sample in use).
    void* loan() noexcept;
    /// Publishes a loaned sample; the loan ends either way. Never throws.
    bool write_loan(void* sample) noexcept;
    /// Gives a loaned sample back unpublished.
    void discard_loan(void* sample) noexcept;
    /// Whether loaned samples live in memory the readers on this host read directly (data
    /// sharing with a plain type: zero copies between the processes).
    bool loans_are_shared() const noexcept;
    size_t matched_subscriptions() const;
    bool wait_for_matched(size_t n, std::chrono::nanoseconds timeout) const;
    /// Waits until every matched reliable reader acknowledged everything written.
    bool wait_for_acknowledgments(std::chrono::nanoseconds timeout);
    const std::string& topic() const;

private:
    void close() noexcept;
    struct Impl;
    std::unique_ptr<Impl> impl_;
};

}  // namespace cpm::detail
