/*  plunit tests of bulk_write.pl: the bytes a frame puts on a real TCP
    socket are those write/2 puts there, whole, in order.
    Run: swipl -g run_tests -t halt test_bulk_write.pl
*/
:- use_module('../../platform_pl/bulk_write').
:- use_module('../../platform_pl/wire').
:- use_module(byte_strings).
:- use_module(library(plunit)).
:- use_module(library(socket)).
:- use_module(library(memfile)).

:- begin_tests(bulk_write).

%   A connected pair of binary socket streams on loopback, as transport.pl
%   sets them up (no position recorded).
with_socket_pair(Goal) :-
    setup_call_cleanup(
        ( tcp_socket(S), tcp_setopt(S, reuseaddr), tcp_bind(S, localhost:Port),
          tcp_listen(S, 1),
          tcp_connect(localhost:Port, Pair, []),
          tcp_accept(S, C, _), tcp_open_socket(C, In, PeerOut),
          stream_pair(Pair, _, Out),
          forall(member(X, [In, Out]),
                 ( set_stream(X, type(binary)), set_stream(X, record_position(false)) ))
        ),
        call(Goal, Out, In-PeerOut),
        ( catch(close(Pair, [force(true)]), _, true),
          catch(close(In, [force(true)]), _, true),
          catch(close(PeerOut, [force(true)]), _, true),
          tcp_close_socket(S) )).

%   Read N bytes of In in a thread (the writer must not wait on a full
%   socket buffer for a reader that has not started).
read_n_async(In, N, Id) :-
    thread_create(( read_string(In, N, S), thread_exit(S) ), Id, []).

joined(Id, S) :-
    thread_join(Id, Status),
    Status = exited(S).

test(native_built, [true(B == true)]) :-
    bulk_write_native(B).

%   2 MB of every byte value, after a small buffered prefix: the reader
%   sees the prefix first, then every byte in order.
test(socket_bytes_whole_and_in_order) :-
    byte_string(2000000, Bytes),
    with_socket_pair([Out, In-_]>>(
        read_n_async(In, 2000005, Id),
        write(Out, "head:"),
        write_bytes(Out, Bytes),
        flush_output(Out),
        joined(Id, Got),
        string_concat("head:", Bytes, Want),
        assertion(Got == Want))).

%   A 100,000-float binary frame over the socket reads back equal.
test(frame_over_socket) :-
    numlist(1, 100000, Is),
    maplist([I, F]>>(F is I / 7.0), Is, Floats),
    Term = transfer(m, move, data(Floats)),
    with_socket_pair([Out, In-_]>>(
        thread_create(( frame_read(In, F, [binary(true), max_size(10000000)]),
                        thread_exit(F) ), Id, []),
        frame_write(Out, binary, Term),
        joined(Id, frame(binary, Got)),
        assertion(Got == Term))).

%   Control: on a text stream (UTF-8) the bulk path is not taken, and the
%   bytes are those of write/2 (a code above 127 is two bytes), which the
%   raw bytes would not be.
test(text_stream_falls_back) :-
    String = "a\u00e9b",
    new_memory_file(MF),
    setup_call_cleanup(open_memory_file(MF, write, Out, [encoding(utf8)]),
                       write_bytes(Out, String), close(Out)),
    memory_file_to_codes(MF, Codes, octet),
    free_memory_file(MF),
    assertion(Codes == [0'a, 0xc3, 0xa9, 0'b]).

%   On an octet memory file the bytes are exactly the string's.
test(memory_file_octet) :-
    byte_string(50000, Bytes),
    new_memory_file(MF),
    setup_call_cleanup(open_memory_file(MF, write, Out, [encoding(octet)]),
                       ( write(Out, "xy"), write_bytes(Out, Bytes) ), close(Out)),
    memory_file_to_string(MF, Got, octet),
    free_memory_file(MF),
    string_concat("xy", Bytes, Want),
    assertion(Got == Want).

test(code_above_255, [error(representation_error(_))]) :-
    with_socket_pair([Out, _]>>write_bytes(Out, "a\u0100")).

%   A write to a socket whose peer is gone raises the error write/2
%   raises there (the control, on a socket of its own): it is not
%   swallowed.
test(peer_gone_raises) :-
    byte_string(4000000, Bytes),
    gone_error(write, Bytes, Want),
    gone_error(write_bytes, Bytes, Got),
    assertion(nonvar(Want)),
    assertion(Got =@= Want).

gone_error(Write, Bytes, Formal) :-
    catch(with_socket_pair([Out, In-PeerOut]>>(
              close(In, [force(true)]),
              close(PeerOut, [force(true)]),
              sleep(0.05),
              call(Write, Out, Bytes),
              call(Write, Out, Bytes),
              flush_output(Out))),
          error(Formal0, _), true),
    (   nonvar(Formal0)
    ->  Formal0 =.. [F|_], Formal = F
    ;   true
    ).

:- end_tests(bulk_write).
