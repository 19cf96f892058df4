:- module(transport,
          [ address_normalize/2,        % +Address, -Host:Port
            address_link/2,             % ?Host:Port, ?(Host,Port)
            transport_open/3,           % +Address, -Conn, +Options
            transport_close/1,          % +Conn
            transport_auth/3,           % +Conn, +Tokens, +Action
            transport_send/3,           % +Conn, +Kind, +Term
            transport_receive/3,        % +Conn, -Reply, +Options
            transport_request/4,        % +Address, +Request, -Result, +Options
            transport_acquire/4,        % +Address, +Tokens, -Conn, +Options
            transport_release/1,        % +Conn
            transport_discard/1,        % +Conn
            transport_drop_pool/0,
            token_proof/3,              % +Token, +Nonce, -Proof
            open_key/1                  % -Token
          ]).
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(platform_errors, [transport_error/2]).
:- autoload(library(socket),
            [tcp_socket/1, tcp_setopt/2, tcp_connect/3, tcp_close_socket/1]).
:- autoload(library(error), [must_be/2, domain_error/2]).
:- autoload(library(option), [option/2, option/3]).
:- autoload(library(sha), [hmac_sha/4]).
:- autoload(library(time), [call_with_time_limit/2]).

/** <module> Client side of the platform protocol

A connection starts with the server sending hello(Version, Nonce, Info).
A client that wants privileged service (agent transfer, code loading)
then sends auth(Proofs): one HMAC-SHA256 of the nonce per token it
holds; tokens themselves never cross the wire. Requests and replies are
frames (see wire.pl); a reply is ok(Result) or error(Error).

Connections have a connect timeout and a reply timeout, and TCP_NODELAY
is set. Nothing a peer replies is ever called.
*/

:- predicate_options(transport_open/3, 3,
                     [ connect_timeout(number),
                       reply_timeout(number)
                     ]).

%!  address_normalize(+Address, -HostPort) is det.
%
%   Accept Host:Port, (Host,Port) or a bare Port (meaning localhost) and
%   return Host:Port.
%
%   @error type_error(address, Address) for anything else.
%   @error domain_error(port, Port) for a port outside 0..65535.

address_normalize(Address, _) :-
    var(Address),
    !,
    throw(error(instantiation_error, _)).
address_normalize(Host:Port, Host:Port) :-
    !,
    check_host(Host),
    check_port(Port).
address_normalize((Host,Port), Host:Port) :-
    !,
    check_host(Host),
    check_port(Port).
address_normalize(Port, localhost:Port) :-
    integer(Port),
    !,
    check_port(Port).
address_normalize(Address, _) :-
    throw(error(type_error(address, Address), _)).

check_host(Host) :-
    must_be(atomic, Host).

check_port(Port) :-
    must_be(integer, Port),
    (   between(0, 65535, Port)
    ->  true
    ;   domain_error(port, Port)
    ).

%!  address_link(?HostPort, ?Link) is det.
%
%   Translate between the native address Host:Port and the Tartarus link
%   (Host,Port) that handlers receive.

address_link(Host:Port, (Host,Port)).

%!  transport_open(+Address, -Conn, +Options) is det.
%
%   Connect to the platform at Address and read its hello. Options:
%
%     - connect_timeout(+Seconds)   default 5
%     - reply_timeout(+Seconds)     default 30
%
%   @error transport_error(Address, Reason)

transport_open(Address0, Conn, Options) :-
    address_normalize(Address0, Address),
    option(connect_timeout(CT), Options, 5),
    option(reply_timeout(RT), Options, 30),
    connect(Address, CT, Pair),
    Conn = conn(Address, Pair, Nonce, Info, RT),
    catch(setup_stream(Pair, RT),
          E, (close(Pair, [force(true)]), throw(E))),
    catch(receive_hello(Conn, Nonce, Info),
          E2, (close(Pair, [force(true)]), throw(E2))).

connect(Address, Timeout, Pair) :-
    catch(call_with_time_limit(Timeout,
                               tcp_connect(Address, Pair,
                                           [nodelay(true), bypass_proxy(true)])),
          E,
          connect_failed(Address, E)).

connect_failed(Address, time_limit_exceeded) :-
    !,
    transport_error(Address, timeout(connect)).
connect_failed(Address, error(socket_error(_Code, Msg), _)) :-
    !,
    transport_error(Address, connect(Msg)).
connect_failed(Address, error(Formal, _)) :-
    !,
    transport_error(Address, connect(Formal)).
connect_failed(_, E) :-
    throw(E).

setup_stream(Pair, Timeout) :-
    stream_pair(Pair, In, Out),
    set_stream(In, type(binary)),
    set_stream(Out, type(binary)),
    set_stream(In, timeout(Timeout)).

receive_hello(Conn, Nonce, Info) :-
    Conn = conn(Address, _, _, _, _),
    receive_frame(Conn, hello, Term),
    (   Term = hello(Version, Nonce, Info)
    ->  (   wire_version(Version)
        ->  true
        ;   transport_error(Address, protocol(version(Version)))
        )
    ;   Term = error(E)
    ->  throw(E)
    ;   transport_error(Address, protocol(expected_hello))
    ).

		 /*******************************
		 *       CONNECTION REUSE		*
		 *******************************/

:- dynamic pooled/4.            % Address, Tokens, Conn, LastUsed

%!  transport_acquire(+Address, +Tokens, -Conn, +Options) is det.
%
%   A connection to Address on which Tokens have been proved (option
%   action(Action) names the permission error if they are refused): a pooled
%   one if a healthy one is idle, else a new one. Give it back with
%   transport_release/1 after a complete request/reply exchange, or
%   transport_discard/1 after any error. Pooled connections idle for
%   more than 5 seconds are closed (servers close idle ones after 10).

transport_acquire(Address0, Tokens, Conn, Options) :-
    address_normalize(Address0, Address),
    msort(Tokens, Key),
    get_time(Now),
    Fresh is Now - 5,
    (   with_mutex(dfrl_transport_pool,
                   take_pooled(Address, Key, Fresh, Conn0))
    ->  Conn = Conn0
    ;   transport_open(Address, Conn, Options),
        option(action(Action), Options, access),
        catch(transport_auth(Conn, Key, Action), E,
              ( transport_close(Conn), throw(E) )),
        remember_key(Conn, Key)
    ).

take_pooled(Address, Key, Fresh, Conn) :-
    retract(pooled(Address, Key, C, Used)),
    (   Used >= Fresh,
        healthy(C)
    ->  Conn = C
    ;   transport_close(C),
        take_pooled(Address, Key, Fresh, Conn)
    ).

%   An idle pooled connection must have nothing to read: readable means
%   the server closed it (or sent garbage).
healthy(conn(_, Pair, _, _, _)) :-
    stream_pair(Pair, In, _),
    catch(wait_for_input([In], Ready, 0), _, fail),
    Ready == [].

remember_key(conn(_, Pair, _, _, _), Key) :-
    retractall(conn_key(Pair, _)),
    assertz(conn_key(Pair, Key)).

:- dynamic conn_key/2.

%!  transport_release(+Conn) is det.
%
%   Return Conn to the pool for reuse.

transport_release(Conn) :-
    Conn = conn(Address, Pair, _, _, _),
    (   conn_key(Pair, Key)
    ->  get_time(Now),
        with_mutex(dfrl_transport_pool, assertz(pooled(Address, Key, Conn, Now)))
    ;   transport_close(Conn)
    ).

%!  transport_discard(+Conn) is det.
%
%   Close Conn instead of returning it to the pool.

transport_discard(Conn) :-
    transport_close(Conn).

%!  transport_drop_pool is det.
%
%   Close every pooled connection.

transport_drop_pool :-
    with_mutex(dfrl_transport_pool,
               forall(retract(pooled(_, _, C, _)), transport_close(C))).

%!  transport_close(+Conn) is det.

transport_close(conn(_, Pair, _, _, _)) :-
    retractall(conn_key(Pair, _)),
    close(Pair, [force(true)]).

%!  transport_auth(+Conn, +Tokens, +Action) is det.
%
%   Prove to the server that we hold Tokens, by sending one HMAC of its
%   nonce per token, and wait for its verdict. The open key is always
%   included, so an open platform (one without tokens) accepts any
%   client.
%
%   @error permission_error(Action, platform, Address) if the server
%   accepts none of the tokens.

transport_auth(Conn, Tokens, Action) :-
    Conn = conn(Address, Pair, Nonce, _, _),
    open_key(Open),
    findall(P, ( member(T, [Open|Tokens]), token_proof(T, Nonce, P) ), Proofs0),
    sort(Proofs0, Proofs),
    stream_pair(Pair, _, Out),
    frame_write(Out, text, auth(Proofs)),
    receive_frame(Conn, auth, Verdict),
    (   Verdict == ok(authenticated)
    ->  true
    ;   Verdict = error(error(permission_error(_, _, _), _))
    ->  throw(error(permission_error(Action, platform, Address),
                    context(_, 'the platform accepts none of the tokens')))
    ;   transport_error(Address, protocol(unexpected_reply(Verdict)))
    ).

%!  open_key(-Token) is det.
%
%   The key an open platform accepts. Knowing it proves nothing; it only
%   keeps accidental garbage (port scans, other protocols) away from the
%   binary decoder.

open_key('dfrl-open-platform').

%!  token_proof(+Token, +Nonce, -Proof) is det.
%
%   Proof is the hex HMAC-SHA256 of Nonce keyed by Token's canonical text.

token_proof(Token, Nonce, Proof) :-
    format(codes(Key), "~q", [Token]),
    atom_codes(Nonce, Data),
    hmac_sha(Key, Data, Hash, [algorithm(sha256)]),
    hash_hex(Hash, Proof).

hash_hex(Bytes, Hex) :-
    phrase(hex_bytes(Bytes), Codes),
    atom_codes(Hex, Codes).

hex_bytes([]) --> [].
hex_bytes([B|Bs]) -->
    { H is B >> 4, L is B /\ 15, code_type(C1, xdigit(H)), code_type(C2, xdigit(L)) },
    [C1, C2],
    hex_bytes(Bs).

%!  transport_send(+Conn, +Kind, +Term) is det.

transport_send(conn(Address, Pair, _, _, _), Kind, Term) :-
    stream_pair(Pair, _, Out),
    catch(frame_write(Out, Kind, Term), E, send_failed(Address, E)).

send_failed(Address, error(io_error(_, _), _)) :-
    !,
    transport_error(Address, closed(send)).
send_failed(Address, error(socket_error(_, Msg), _)) :-
    !,
    transport_error(Address, closed(send(Msg))).
send_failed(_, E) :-
    throw(E).

%!  transport_receive(+Conn, -Term, +Options) is det.
%
%   Read one reply frame. Options: phase(Phase), used in error terms.
%
%   @error transport_error(Address, timeout(Phase)) if no reply came in
%   the connection's reply timeout, closed(Phase) if the peer closed it.

transport_receive(Conn, Term, Options) :-
    option(phase(Phase), Options, reply),
    receive_frame(Conn, Phase, Term).

receive_frame(conn(Address, Pair, _, _, _), Phase, Term) :-
    stream_pair(Pair, In, _),
    catch(frame_read(In, Frame, [max_size(268435456)]), E,
          receive_failed(Address, Phase, E)),
    (   Frame = frame(_, Term)
    ->  true
    ;   transport_error(Address, closed(Phase))
    ).

receive_failed(Address, Phase, error(timeout_error(_, _), _)) :-
    !,
    transport_error(Address, timeout(Phase)).
receive_failed(Address, Phase, error(io_error(_, _), _)) :-
    !,
    transport_error(Address, closed(Phase)).
receive_failed(Address, Phase, error(socket_error(_, _), _)) :-
    !,
    transport_error(Address, closed(Phase)).
receive_failed(Address, _Phase, error(wire_error(R), _)) :-
    !,
    transport_error(Address, protocol(R)).
receive_failed(_, _, E) :-
    throw(E).

%!  transport_request(+Address, +Request, -Result, +Options) is det.
%
%   Send Request as a text frame on a fresh connection and wait for the
%   reply. If the reply is ok(Result), unify Result; if it is
%   error(error(Formal, _)), throw error(Formal, remote(Address)).
%   Options are those of transport_open/3 plus tokens(List): prove these
%   tokens first (for privileged requests).

transport_request(Address, Request, Result, Options) :-
    setup_call_cleanup(
        transport_open(Address, Conn, Options),
        request_on(Conn, Request, Reply, Options),
        transport_close(Conn)),
    reply_result(Address, Reply, Result).

request_on(Conn, Request, Reply, Options) :-
    (   option(tokens(Tokens), Options)
    ->  option(action(Action), Options, access),
        transport_auth(Conn, Tokens, Action)
    ;   true
    ),
    option(kind(Kind), Options, text),
    transport_send(Conn, Kind, Request),
    transport_receive(Conn, Reply, []).

reply_result(_, ok(Result0), Result) :-
    !,
    Result = Result0.
reply_result(Address, error(error(Formal, _)), _) :-
    !,
    throw(error(Formal, remote(Address))).
reply_result(Address, Other, _) :-
    transport_error(Address, protocol(unexpected_reply(Other))).
