#pragma once
// The store's sequences (Store.cpp): an object's records and its data-time index.
#include <algorithm>
#include <cstddef>
#include <vector>

namespace cpm::rtdb::detail {

/// A sequence in one circular buffer, oldest first (contiguous, so a lookup by index is an add
/// and a compare, not a deque's block walk). It grows by a quarter at a time: little unused
/// room per element, still amortised O(1) appends at the back and removals at the front. It
/// never drops an element by itself: the store evicts with pop_front(). Not thread-safe.
template <typename T>
class Ring
{
public:
    size_t size() const { return n_; }
    bool empty() const { return n_ == 0; }
    /// Elements it has room for before it grows.
    size_t capacity() const { return buf_.size(); }
    const T& operator[](size_t i) const { return buf_[slot(i)]; }
    T& operator[](size_t i) { return buf_[slot(i)]; }
    const T& front() const { return (*this)[0]; }
    const T& back() const { return (*this)[n_ - 1]; }
    void push_back(const T& x)
    {
        if (n_ == buf_.size()) resize(std::max<size_t>(16, buf_.size() + buf_.size() / 4));
        buf_[slot(n_++)] = x;
    }
    void pop_front()
    {
        if (++head_ == buf_.size()) head_ = 0;
        --n_;
    }
    /// Inserts before index i, moving the elements after it (cheap near the back).
    void insert(size_t i, const T& x)
    {
        push_back(x);
        for (size_t k = n_ - 1; k > i; --k) (*this)[k] = (*this)[k - 1];
        (*this)[i] = x;
    }
    /// Removes index i, moving the elements before it (cheap near the front).
    void erase(size_t i)
    {
        for (size_t k = i; k > 0; --k) (*this)[k] = (*this)[k - 1];
        pop_front();
    }
    /// Gives memory back after a flood has passed.
    void shrink()
    {
        if (buf_.size() > 64 && n_ < buf_.size() / 2) resize(std::max<size_t>(16, n_ + n_ / 4));
    }

private:
    size_t slot(size_t i) const
    {
        size_t k = head_ + i;
        return k >= buf_.size() ? k - buf_.size() : k;
    }
    void resize(size_t capacity)
    {
        std::vector<T> next(capacity);
        for (size_t i = 0; i < n_; ++i) next[i] = (*this)[i];
        buf_.swap(next);
        head_ = 0;
    }
    std::vector<T> buf_;
    size_t head_ = 0, n_ = 0;
};

}  // namespace cpm::rtdb::detail
