/*  plunit cases of tls.pl's direct write (native/tls_direct.c): over a
    real mutual-TLS connection on loopback, the client's and the server's
    TLS records go straight to the socket, the bytes arrive whole and in
    order both ways, a refused swap leaves the connection as it was, and a
    peer that has gone makes a write raise, not kill the process.
    The certificates come from the folder in DFRL_TLS_DIR (node.crt,
    node.key, ca.crt), which test_tls_direct.py makes.
    Run: DFRL_TLS_DIR=DIR swipl -g run_tests -t halt tls_direct_cases.pl
*/
:- use_module('../../platform_pl/tls').
:- use_module('../../platform_pl/bulk_write').
:- use_module(byte_strings).
:- use_module(library(plunit)).
:- use_module(library(socket)).

:- begin_tests(tls_direct).

dir(Dir) :-
    getenv('DFRL_TLS_DIR', Dir).

%   A mutual-TLS connection over loopback: Goal is called with the
%   client's plain and TLS pairs and the server's.
with_tls_pair(Goal) :-
    dir(Dir),
    setup_call_cleanup(
        ( tcp_socket(S), tcp_setopt(S, reuseaddr), tcp_bind(S, '127.0.0.1':Port),
          tcp_listen(S, 1),
          thread_create(server_side(S, Dir), Server, []),
          tcp_connect('127.0.0.1':Port, CPlain, []),
          binary_pair(CPlain),
          tls_connect(Dir, '127.0.0.1':Port, CPlain, CTls, [timeout(10)]),
          thread_join(Server, exited(SPlain-STls))
        ),
        call(Goal, CPlain-CTls, SPlain-STls),
        ( catch(close(CTls, [force(true)]), _, true),
          catch(close(STls, [force(true)]), _, true),
          tcp_close_socket(S) )).

server_side(S, Dir) :-
    tcp_accept(S, C, _),
    tcp_open_socket(C, SPlain),
    binary_pair(SPlain),
    tls_accept(Dir, SPlain, STls, _Peer, [deadline(10)]),
    thread_exit(SPlain-STls).

binary_pair(Pair) :-
    stream_pair(Pair, In, Out),
    set_stream(In, type(binary)),
    set_stream(Out, type(binary)).

write_bio(Plain-Tls, Kind) :-
    stream_pair(Plain, In0, Out0),
    stream_pair(Tls, _, Out),
    tls:tls_write_bio(Out, In0, Out0, Kind).

%   Bytes written to From arrive at To whole and in order (a reader
%   thread, so the writer never waits on a full socket for it). Compared
%   by equality; a mismatch reports lengths, not megabytes of text.
send_and_check(From, To, Bytes) :-
    send_and_check(From, To, "", Bytes).

send_and_check(From, To, Prefix, Bytes) :-
    string_concat(Prefix, Bytes, Want),
    string_length(Want, N),
    stream_pair(To, In, _),
    thread_create(( read_string(In, N, S), thread_exit(S) ), Id, []),
    stream_pair(From, _, Out),
    write(Out, Prefix),
    write_bytes(Out, Bytes),
    flush_output(Out),
    thread_join(Id, Status),
    (   Status = exited(Got), Got == Want
    ->  true
    ;   Status = exited(Got)
    ->  string_length(Got, GotN),
        format(user_error, "received ~w bytes, not the ~w sent~n", [GotN, N]),
        fail
    ;   format(user_error, "reader: ~q~n", [Status]),
        fail
    ).

test(library_built, [true(D == true)]) :-
    tls:direct(D).

%   Both ends of a connection the platform negotiates write to the socket.
test(both_ends_direct) :-
    with_tls_pair([C, S]>>( write_bio(C, K1), write_bio(S, K2),
                            assertion([K1, K2] == [socket, socket]) )).

%   3 MB each way, after a small buffered prefix, arrive equal.
test(bytes_whole_both_ways) :-
    byte_string(3000000, Bytes),
    with_tls_pair([C-CT, S-ST]>>(
        write_bio(C-CT, socket),
        write_bio(S-ST, socket),
        send_and_check(CT, ST, "head:", Bytes),
        send_and_check(ST, CT, "back:", Bytes))).

%   A swap whose streams are not the connection's is refused, and the
%   connection still writes through ssl4pl's stream BIO.
test(swap_refused_for_other_streams) :-
    with_tls_pair([C-CT, S-ST]>>(
        stream_pair(CT, _, COut),
        stream_pair(S, SIn0, SOut0),
        assertion(\+ tls:tls_direct_write(COut, SIn0, SOut0)),
        assertion(\+ tls:tls_write_bio(COut, SIn0, SOut0, _)),
        write_bio(C-CT, socket),
        byte_string(100000, Bytes),
        send_and_check(CT, ST, Bytes))).

%   Streams that are no TLS connection's (a file's handle is a descriptor,
%   a socket's is no ssl4pl record): refused, without touching them.
test(swap_refused_for_non_tls_streams) :-
    assertion(\+ tls:tls_direct_write(user_output, user_input, user_output)),
    assertion(\+ tls:tls_write_bio(user_output, user_input, user_output, _)),
    with_tls_pair([C-_, _]>>(
        stream_pair(C, In0, Out0),
        assertion(\+ tls:tls_direct_write(Out0, In0, Out0)))).

%   Control for both_ends_direct: a connection made by ssl4pl alone writes
%   through its stream BIO (so `socket` above is the swap's doing).
test(ssl4pl_alone_writes_through_its_stream) :-
    dir(Dir),
    setup_call_cleanup(
        plain_tls(Dir, CPlain, CT, ST),
        ( write_bio(CPlain-CT, Kind),
          assertion(Kind == other),
          byte_string(100000, Bytes),
          send_and_check(CT, ST, Bytes) ),
        ( close(CT, [force(true)]), close(ST, [force(true)]) )).

%   A connection negotiated with ssl_negotiate/5 directly (no tls.pl).
plain_tls(Dir, CPlain, CTls, STls) :-
    directory_file_path(Dir, 'node.crt', Cert),
    directory_file_path(Dir, 'node.key', Key),
    directory_file_path(Dir, 'ca.crt', CA),
    Opts = [certificate_file(Cert), key_file(Key), cacerts([file(CA)]),
            cert_verify_hook(tls:ca_signed), close_parent(true)],
    ssl_context(server, SCtx, Opts),
    ssl_context(client, CCtx, Opts),
    tcp_socket(L), tcp_setopt(L, reuseaddr), tcp_bind(L, '127.0.0.1':Port), tcp_listen(L, 1),
    thread_create(( tcp_accept(L, A, _), tcp_open_socket(A, SP), binary_pair(SP),
                    stream_pair(SP, SI, SO),
                    ssl_negotiate(SCtx, SI, SO, I, O), stream_pair(ST, I, O),
                    thread_exit(ST) ), Id, []),
    tcp_connect('127.0.0.1':Port, CPlain, []),
    binary_pair(CPlain),
    stream_pair(CPlain, CI, CO),
    ssl_negotiate(CCtx, CI, CO, I2, O2),
    stream_pair(CTls, I2, O2),
    thread_join(Id, exited(STls)),
    tcp_close_socket(L).

%   The peer has closed: writing raises an I/O error (no SIGPIPE death),
%   and this process goes on.
test(write_to_a_gone_peer_raises) :-
    byte_string(1000000, Bytes),
    with_tls_pair([_-CT, _-ST]>>(
        close(ST, [force(true)]),
        stream_pair(CT, _, COut),
        catch(( between(1, 50, _),
                write_bytes(COut, Bytes), flush_output(COut),
                fail
              ; true ),
              E, true),
        assertion(nonvar(E)),
        assertion(( E = error(io_error(write, _), _)           % this BIO
                  ; E = error(socket_error(epipe, _), _) )))).

:- end_tests(tls_direct).
