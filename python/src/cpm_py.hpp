#pragma once
// The pieces of cpm's Python module that the generated bindings (gen_types.py) use: each Python
// value checked against its IDL type with an error naming the field, lists to and from IDL
// sequences and arrays, and the typed readers and writers of one topic type.
#include <cpm/AsyncReader.hpp>
#include <cpm/HistoryClient.hpp>
#include <cpm/Logging.hpp>
#include <cpm/MultiVehicleReader.hpp>
#include <cpm/Participant.hpp>
#include <cpm/Reader.hpp>
#include <cpm/Writer.hpp>

#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <string>
#include <vector>

namespace cpm_py {

namespace py = pybind11;

inline std::string type_name(py::handle v) { return py::str(py::type::handle_of(v).attr("__name__")).cast<std::string>(); }

/// An integer of the IDL type `idl` (octet, long, …): TypeError for a non-integer (a bool
/// too), ValueError naming the field and the range for one out of it.
template <class T>
T to_int(py::handle v, const std::string& what, const char* idl)
{
    if (!PyLong_Check(v.ptr()) || PyBool_Check(v.ptr())) {
        throw py::type_error(what + ": expected an integer (IDL " + idl + "), got " + type_name(v));
    }
    int overflow = 0;
    if constexpr (std::is_signed_v<T>) {
        const long long x = PyLong_AsLongLongAndOverflow(v.ptr(), &overflow);
        if (overflow == 0 && x >= (long long)std::numeric_limits<T>::min() && x <= (long long)std::numeric_limits<T>::max()) return T(x);
    } else {
        const unsigned long long x = PyLong_AsUnsignedLongLong(v.ptr());
        if (PyErr_Occurred()) PyErr_Clear();
        else if (x <= (unsigned long long)std::numeric_limits<T>::max()) return T(x);
    }
    throw py::value_error(what + ": " + py::str(v).cast<std::string>() + " is out of range for IDL " + idl + " (" +
                          std::to_string((long long)std::numeric_limits<T>::min()) + ".." +
                          std::to_string((unsigned long long)std::numeric_limits<T>::max()) + ")");
}

/// A float or an int (NaN and infinities are values of the IDL type: a car's bridge refuses them).
template <class T>
T to_float(py::handle v, const std::string& what)
{
    if (PyBool_Check(v.ptr()) || (!PyFloat_Check(v.ptr()) && !PyLong_Check(v.ptr()))) {
        throw py::type_error(what + ": expected a number, got " + type_name(v));
    }
    const double x = PyFloat_AsDouble(v.ptr());
    if (std::is_same_v<T, float> && std::isfinite(x) && std::abs(x) > double(std::numeric_limits<float>::max())) {
        throw py::value_error(what + ": " + py::str(v).cast<std::string>() + " is out of range for IDL float");
    }
    return T(x);
}

inline bool to_bool(py::handle v, const std::string& what)
{
    if (!PyBool_Check(v.ptr())) throw py::type_error(what + ": expected True or False, got " + type_name(v));
    return v.ptr() == Py_True;
}

inline std::string to_str(py::handle v, const std::string& what)
{
    if (!PyUnicode_Check(v.ptr())) throw py::type_error(what + ": expected a str, got " + type_name(v));
    return v.cast<std::string>();
}

template <class E>
E to_enum(py::handle v, const std::string& what, int count)
{
    if (py::isinstance<E>(v)) return v.cast<E>();
    const int x = to_int<int32_t>(v, what, "enum");
    if (x < 0 || x >= count) throw py::value_error(what + ": " + std::to_string(x) + " is no value of its enum (0.." + std::to_string(count - 1) + ")");
    return E(x);
}

template <class S>
S to_struct(py::handle v, const std::string& what, const char* idl)
{
    if (!py::isinstance<S>(v)) throw py::type_error(what + ": expected a " + idl + ", got " + type_name(v));
    return v.cast<S>();
}

inline std::vector<uint8_t> to_octets(py::handle v, const std::string& what, size_t bound)
{
    std::vector<uint8_t> out;
    if (PyBytes_Check(v.ptr()) || PyByteArray_Check(v.ptr())) {
        const std::string bytes = py::bytes(py::reinterpret_borrow<py::object>(v)).cast<std::string>();
        out.assign(bytes.begin(), bytes.end());
    } else if (py::isinstance<py::iterable>(v) && !PyUnicode_Check(v.ptr())) {
        size_t i = 0;
        for (auto item : v) out.push_back(to_int<uint8_t>(item, what + "[" + std::to_string(i++) + "]", "octet"));
    } else {
        throw py::type_error(what + ": expected bytes, got " + type_name(v));
    }
    if (bound && out.size() > bound) throw py::value_error(what + ": " + std::to_string(out.size()) + " bytes, at most " + std::to_string(bound));
    return out;
}

template <class T>
py::list to_list(const std::vector<T>& values)
{
    py::list out;
    for (const auto& x : values) out.append(py::cast(x));
    return out;
}
template <class T, size_t N>
py::list to_list(const std::array<T, N>& values)
{
    py::list out;
    for (const auto& x : values) out.append(py::cast(x));
    return out;
}

/// A Python list (any iterable but a str) into a sequence: each element converted by `convert`,
/// which names the element (`what[i]`); a sequence longer than its bound, or an array of the
/// wrong length, is a ValueError.
template <class Container, class Convert>
void from_list(py::handle list, const std::string& what, size_t bound, bool fixed, Container& target, Convert convert)
{
    if (!py::isinstance<py::iterable>(list) || PyUnicode_Check(list.ptr())) throw py::type_error(what + ": expected a list, got " + type_name(list));
    std::vector<typename Container::value_type> values;
    size_t i = 0;
    for (auto item : list) values.push_back(convert(item, what + "[" + std::to_string(i++) + "]"));
    if (fixed && values.size() != bound) {
        throw py::value_error(what + ": expected exactly " + std::to_string(bound) + " elements, got " + std::to_string(values.size()));
    }
    if (!fixed && bound && values.size() > bound) {
        throw py::value_error(what + ": " + std::to_string(values.size()) + " elements, at most " + std::to_string(bound));
    }
    if constexpr (std::is_same_v<Container, std::vector<typename Container::value_type>>) {
        target = std::move(values);
    } else {
        std::copy(values.begin(), values.end(), target.begin());
    }
}

/// The GIL for a call into Python from one of cpm's threads. The thread's Python state is made
/// once and kept (pybind11 would make and delete one per call: tens of microseconds each).
class CallbackGil
{
public:
    CallbackGil()
    {
        thread_local bool kept = false;
        if (!kept) {
            gil_.inc_ref();
            kept = true;
        }
    }

private:
    py::gil_scoped_acquire gil_;
};

/// A Python function C++ keeps (in a callback): shared by the copies, deleted with the GIL held
/// whichever thread lets go of it last.
inline std::shared_ptr<py::function> keep(py::function f)
{
    return std::shared_ptr<py::function>(new py::function(std::move(f)), [](py::function* p) {
        py::gil_scoped_acquire gil;
        delete p;
    });
}

/// The participant a Python reader or writer is made on: the given one, or the process's.
inline cpm::Participant& participant_of(cpm::Participant* p) { return p ? *p : cpm::Participant::default_participant(); }

/// An AsyncReader whose callback runs Python: the GIL taken for the call, released while the
/// reader is destroyed (its thread may be waiting for it). An exception in the callback is
/// logged with its traceback; the reader goes on.
template <class T>
class PyAsyncReader
{
public:
    PyAsyncReader(py::function callback, const std::string& topic, cpm::ReaderOptions options, cpm::Participant* participant)
        : callback_(keep(std::move(callback)))
    {
        auto cb = callback_;
        const std::string where = topic;
        py::gil_scoped_release release;
        reader_ = std::make_unique<cpm::AsyncReader<T>>(
            [cb, where](std::vector<T>& samples) {
                CallbackGil gil;
                try {
                    (*cb)(samples);
                } catch (py::error_already_set& e) {
                    CPM_LOG_ERROR("python AsyncReader on %s: the callback raised:\n%s", where.c_str(), e.what());
                }
            },
            participant_of(participant), topic, options);
    }
    ~PyAsyncReader() { close(); }
    void close()
    {
        if (!reader_) return;
        if (!PyGILState_Check()) {
            reader_.reset();
            return;
        }
        py::gil_scoped_release release;  // its thread may be waiting for the GIL
        reader_.reset();
    }
    size_t matched_publications() const { return reader_ ? reader_->matched_publications() : 0; }

private:
    std::shared_ptr<py::function> callback_;
    std::unique_ptr<cpm::AsyncReader<T>> reader_;
};

/// Reader_T and SampleResult_T of a stamped type; MultiVehicleReader_T of a keyed one.
template <class T, bool keyed>
void bind_stamped(py::module_& m, const std::string& name)
{
    py::class_<cpm::SampleResult<T>>(m, ("SampleResult_" + name).c_str())
        .def_readonly("sample", &cpm::SampleResult<T>::sample)
        .def_readonly("valid", &cpm::SampleResult<T>::valid)
        .def_readonly("age_ns", &cpm::SampleResult<T>::age_ns)
        .def("__repr__", [name](const cpm::SampleResult<T>& r) {
            return "SampleResult(valid=" + std::string(r.valid ? "True" : "False") + ", age_ns=" + std::to_string(r.age_ns) + ", sample=<" + name + ">)";
        });
    py::class_<cpm::Reader<T>>(m, ("Reader_" + name).c_str())
        .def(py::init([](const std::string& topic, cpm::ReaderOptions o, cpm::Participant* p) {
                 py::gil_scoped_release release;
                 return std::make_unique<cpm::Reader<T>>(participant_of(p), topic, o);
             }),
             py::arg("topic"), py::arg("options"), py::arg("participant") = nullptr, py::keep_alive<1, 4>())
        .def("get_sample", [](cpm::Reader<T>& r, uint64_t t) { return r.get_sample(t); })
        .def("matched_publications", &cpm::Reader<T>::matched_publications)
        .def("wait_for_matched", [](cpm::Reader<T>& r, size_t n, double timeout_s) {
            py::gil_scoped_release release;
            return r.wait_for_matched(n, std::chrono::milliseconds(int64_t(timeout_s * 1000)));
        });
    if constexpr (keyed) {
        py::class_<cpm::MultiVehicleReader<T>>(m, ("MultiVehicleReader_" + name).c_str())
            .def(py::init([](const std::string& topic, std::vector<uint8_t> ids, cpm::ReaderOptions o, cpm::Participant* p) {
                     py::gil_scoped_release release;
                     return std::make_unique<cpm::MultiVehicleReader<T>>(participant_of(p), topic, std::move(ids), o);
                 }),
                 py::arg("topic"), py::arg("vehicle_ids"), py::arg("options"), py::arg("participant") = nullptr, py::keep_alive<1, 5>())
            .def("get_samples", [](cpm::MultiVehicleReader<T>& r, uint64_t t) { return r.get_samples(t); })
            .def("matched_publications", &cpm::MultiVehicleReader<T>::matched_publications);
    }
}


/// Writer_T and AsyncReader_T; for a stamped type (Header first) Reader_T and SampleResult_T,
/// and for a stamped keyed type MultiVehicleReader_T.
template <class T, bool keyed, bool stamped>
void bind_topic(py::module_& m, const std::string& name)
{
    py::class_<cpm::Writer<T>>(m, ("Writer_" + name).c_str())
        .def(py::init([](const std::string& topic, cpm::WriterOptions o, cpm::Participant* p) {
                 py::gil_scoped_release release;
                 return std::make_unique<cpm::Writer<T>>(participant_of(p), topic, o);
             }),
             py::arg("topic"), py::arg("options"), py::arg("participant") = nullptr, py::keep_alive<1, 4>())
        .def("write", [](cpm::Writer<T>& w, const T& sample) {
            py::gil_scoped_release release;
            return w.write(sample);
        })
        .def("matched_subscriptions", &cpm::Writer<T>::matched_subscriptions)
        .def("wait_for_matched", [](cpm::Writer<T>& w, size_t n, double timeout_s) {
            py::gil_scoped_release release;
            return w.wait_for_matched(n, std::chrono::milliseconds(int64_t(timeout_s * 1000)));
        });
    // A history sample's payload (CDR, encapsulation included) as T; None when it is not one.
    m.def(("decode_" + name).c_str(), [](py::bytes payload) -> py::object {
        const std::string b = payload;
        T out;
        if (!cpm::HistoryClient::decode_payload(std::vector<uint8_t>(b.begin(), b.end()), out)) return py::none();
        return py::cast(std::move(out));
    });
    py::class_<PyAsyncReader<T>>(m, ("AsyncReader_" + name).c_str())
        .def(py::init<py::function, const std::string&, cpm::ReaderOptions, cpm::Participant*>(), py::arg("callback"), py::arg("topic"),
             py::arg("options"), py::arg("participant") = nullptr, py::keep_alive<1, 5>())
        .def("close", &PyAsyncReader<T>::close)
        .def("matched_publications", &PyAsyncReader<T>::matched_publications);
    if constexpr (stamped) bind_stamped<T, keyed>(m, name);
}
}  // namespace cpm_py
