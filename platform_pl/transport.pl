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
            transport_peer_id/2,        % +Conn, -Id
            transport_identify/3,       % +Address, -Id, +Options
            transport_pool_statistics/1, % -Stats
            token_proof/3,              % +Token, +Nonce, -Proof
            open_key/1                  % -Token
          ]).
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(platform_errors, [transport_error/2, inert_error/2]).
:- use_module(tls, [tls_connect/5]).
:- use_module(timed_connect, [timed_connect/4]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(socket),
            [tcp_socket/1, tcp_setopt/2, tcp_connect/3, tcp_close_socket/1]).
:- use_module(library(error), [must_be/2, domain_error/2]).
:- use_module(library(option), [option/2, option/3]).
:- use_module(library(sha), [hmac_sha/4]).
:- use_module(library(lists), [member/2, min_list/2]).
:- use_module(library(aggregate), [aggregate_all/3]).

/** <module> Client side of the platform protocol

A connection starts with the server sending hello(Version, Nonce, Info).
A client that wants privileged service (agent transfer, code loading)
then sends auth(Proofs): one HMAC-SHA256 of the nonce per token it
holds; tokens themselves never cross the wire. Requests and replies are
frames (see wire.pl); a reply is ok(Result) or error(Error).

The hello's Info is node(Host, Port, Props): the address the server
advertises and a list with its node id, id(Id), and how long it lets a
connection be silent, idle(Sec) before a token proof and auth_idle(Sec)
after one. "Is this address that node?" is decided by comparing ids
(transport_identify/3), never address text.

Connections have a connect timeout and a reply timeout, and TCP_NODELAY
is set. Requests and migrations reuse pooled connections, which a
janitor thread keeps alive with pings (see transport_acquire/4). Nothing
a peer replies is ever called.
*/

:- predicate_options(transport_open/3, 3,
                     [ connect_timeout(number),
                       reply_timeout(number),
                       tls(any)
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
%     - connect_timeout(+Seconds)   default 5 (the TLS handshake
%                                   has as long again)
%     - reply_timeout(+Seconds)     default 30
%     - tls(+Dir)                   speak TLS with the certificate in
%                                   Dir (see tls.pl), or tls(none) for
%                                   plaintext. Default: as the calling
%                                   thread's node (its tls(Dir) option)
%
%   @error transport_error(Address, Reason)

transport_open(Address0, Conn, Options) :-
    address_normalize(Address0, Address),
    option(connect_timeout(CT), Options, 5),
    option(reply_timeout(RT), Options, 30),
    own_tls(Options, Tls),
    connect(Address, CT, Plain),
    (   Tls == none
    ->  Pair = Plain,
        stream_pair(Plain, _, PlainOut),
        set_stream(PlainOut, buffer_size(65536))    % see setup_stream/2
    ;   catch(tls_connect(Tls, Address, Plain, Pair, [timeout(CT)]),
              E0, (close(Plain, [force(true)]), throw(E0))),
        with_mutex(dfrl_transport_pool, assertz(conn_tls(Pair, Tls)))
    ),
    Conn = conn(Address, Pair, Nonce, Info, RT),
    catch(setup_stream(Pair, RT),
          E, (close(Pair, [force(true)]), throw(E))),
    catch(receive_hello(Conn, Nonce, Info),
          E2, (close(Pair, [force(true)]), throw(E2))),
    remember_peer(Conn).

%   The TLS directory of a connection: the option, else the one of the
%   calling thread's node, else none.
own_tls(Options, Tls) :-
    (   option(tls(T), Options)
    ->  Tls = T
    ;   catch(node:current_node(Node), _, fail),
        node:node_property(Node, option(tls(T)))
    ->  Tls = T
    ;   Tls = none
    ).

%   Bounded by timed_connect/4, not call_with_time_limit/2: a robot
%   process's Prolog runs without signals (see timed_connect.pl).
connect(Address, Timeout, Pair) :-
    catch(timed_connect(Address, Pair, Timeout,
                        [nodelay(true), bypass_proxy(true)]),
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

%   No position is recorded on a connection's streams: SWI-Prolog then
%   moves a binary frame's body in bulk (see wire.pl). A plaintext
%   connection's output buffer is 64 KiB (transport_open/3; tls.pl sizes
%   a TLS one's): a frame then leaves in one send(2) per 64 KiB instead
%   of one per 4 KiB, and wakes the reader as many times fewer.
setup_stream(Pair, Timeout) :-
    stream_pair(Pair, In, Out),
    set_stream(In, type(binary)),
    set_stream(Out, type(binary)),
    set_stream(In, record_position(false)),
    set_stream(Out, record_position(false)),
    set_stream(In, timeout(Timeout)).

receive_hello(Conn, Nonce, Info) :-
    Conn = conn(Address, _, _, _, _),
    receive_frame(Conn, hello, Term),
    (   Term = hello(Version, Nonce, Info)
    ->  (   wire_version(Version)
        ->  true
        ;   transport_error(Address, protocol(version(Version)))
        )
    ;   Term = error(E0)
    ->  inert_error(E0, E),
        throw(E)
    ;   transport_error(Address, protocol(expected_hello))
    ).

		 /*******************************
		 *            IDENTITY		*
		 *******************************/

:- dynamic
    peer_seen/3,                % Address, Id, Time: the id in its last hello
    peer_unreachable/2.         % Address, Time: the last failed identify

%!  transport_peer_id(+Conn, -Id) is semidet.
%
%   Id is the node id the peer announced in its hello on Conn (an atom
%   of 32 hex digits). Fails for a peer that announced none.

transport_peer_id(conn(_, _, _, Info, _), Id) :-
    hello_prop(Info, id(Id)).

hello_prop(node(_, _, Props), Prop) :-
    is_list(Props),
    memberchk(Prop, Props).

remember_peer(Conn) :-
    Conn = conn(Address, _, _, _, _),
    (   transport_peer_id(Conn, Id)
    ->  get_time(Now),
        Old is Now - 60,
        with_mutex(dfrl_transport_pool,
                   ( retractall(peer_seen(Address, _, _)),
                     retractall(peer_unreachable(Address, _)),
                     forall(( peer_seen(A, I, T), T < Old ),
                            retract(peer_seen(A, I, T))),
                     assertz(peer_seen(Address, Id, Now))
                   ))
    ;   true
    ).

%!  transport_identify(+Address, -Id, +Options) is det.
%
%   Id is the node id of the platform that answers at Address: from a
%   healthy pooled connection to Address, else from a hello seen there in
%   the last 60 seconds (and not before since(Time)), else from the hello
%   of a new connection, which is then pooled (unauthenticated) for the
%   request that usually follows. A failed attempt is remembered for 2
%   seconds, so that "is it me?" followed by a request to an unreachable
%   address waits for one connect timeout, not two. Options: those of
%   transport_open/3 and since(+Time).
%
%   @error transport_error(Address, Reason) if Address cannot be reached
%   or announces no id.

transport_identify(Address0, Id, Options) :-
    address_normalize(Address0, Address),
    option(since(Since), Options, 0),
    get_time(Now),
    (   with_mutex(dfrl_transport_pool, known_id(Address, Since, Now, Id0))
    ->  Id = Id0
    ;   with_mutex(dfrl_transport_pool,
                   ( peer_unreachable(Address, T), T >= Now - 2 ))
    ->  transport_error(Address, connect(recently_unreachable))
    ;   catch(transport_open(Address, Conn, Options), E,
              ( with_mutex(dfrl_transport_pool,
                           ( retractall(peer_unreachable(Address, _)),
                             assertz(peer_unreachable(Address, Now)) )),
                throw(E) )),
        (   transport_peer_id(Conn, Id0)
        ->  Id = Id0,
            release(Conn, none)
        ;   transport_close(Conn),
            transport_error(Address, protocol(no_node_id))
        )
    ).

known_id(Address, _, _, Id) :-
    pooled(Address, _, Conn, _, _),
    healthy(Conn),
    transport_peer_id(Conn, Id),
    !.
known_id(Address, Since, Now, Id) :-
    peer_seen(Address, Id, T),
    T >= Since,
    T >= Now - 60,
    !.

		 /*******************************
		 *       CONNECTION REUSE		*
		 *******************************/

/*  The pool keeps idle connections, each under the key of what was proved
    on it: `none` (nothing: a connection opened to learn a peer's id) or
    the sorted list of tokens. An entry is pooled(Address, Key, Conn, Used,
    Checked): Used is when a request last completed on it, Checked when
    traffic last crossed it (a request or a keepalive ping).

    The server closes a connection that stays silent for its idle timeout
    (idle(S) in its hello, before a token proof; auth_idle(S) after). A
    janitor thread, running while the pool is not empty, closes pooled
    connections the peer has closed, closes unauthenticated ones before
    the server would, and pings authenticated ones that have been silent
    for the keepalive interval, so that they survive rests of any length.
    At most `dfrl_pool_max` connections are kept; releasing one more
    closes the least recently used.
*/

:- create_prolog_flag(dfrl_keepalive, 20, [type(float), keep(true)]).
:- create_prolog_flag(dfrl_pool_max, 32, [type(integer), keep(true)]).

:- dynamic
    pooled/5,                   % Address, Key, Conn, Used, Checked
    pinging/4,                  % Address, Key, Conn, Until: out for a ping
    conn_key/2,                 % Pair, Key
    conn_tls/2,                 % Pair, Dir: a TLS connection
    janitor_running/0.

%!  transport_acquire(+Address, +Tokens, -Conn, +Options) is det.
%
%   A connection to Address on which Tokens have been proved (option
%   action(Action) names the permission error if they are refused): a
%   healthy pooled one if there is one (an unauthenticated pooled one is
%   authenticated first), else a new one. A pooled connection found
%   broken, or older than its server's idle limit, is closed and replaced
%   transparently. Give it back with transport_release/1 after a complete
%   request/reply exchange, or transport_discard/1 after any error.
%
%   @error permission_error(Action, platform, Address) if the platform
%   accepts none of the tokens.
%   @error transport_error(Address, Reason)

transport_acquire(Address0, Tokens, Conn, Options) :-
    must_be(list, Tokens),
    msort(Tokens, Key),
    acquire(Address0, Key, Conn, Options).

acquire(Address0, Key, Conn, Options) :-
    address_normalize(Address0, Address),
    own_tls(Options, Tls),
    (   take_pooled_wait(Address, Key, Tls, Conn1, Had)
    ->  reply_timeout(Conn1, Options, Conn0),
        (   Had == Key
        ->  Conn = Conn0
        ;   Key == none
        ->  Conn = Conn0
        ;   authenticate(Conn0, Key, Options),
            Conn = Conn0
        )
    ;   transport_open(Address, Conn, Options),
        (   Key == none
        ->  remember_key(Conn, none)
        ;   authenticate(Conn, Key, Options)
        )
    ).

%   A pooled connection serves this request with the reply timeout it
%   asks for.
reply_timeout(Conn0, Options, Conn) :-
    Conn0 = conn(Address, Pair, Nonce, Info, RT0),
    (   option(reply_timeout(RT), Options), RT =\= RT0
    ->  stream_pair(Pair, In, _),
        set_stream(In, timeout(RT)),
        Conn = conn(Address, Pair, Nonce, Info, RT)
    ;   Conn = Conn0
    ).

authenticate(Conn, Key, Options) :-
    option(action(Action), Options, access),
    catch(transport_auth(Conn, Key, Action), E,
          ( transport_close(Conn), throw(E) )),
    remember_key(Conn, Key).

%   A connection out for a keepalive ping is back within one round trip
%   (at most 5 s): wait for it rather than open a new one.
take_pooled_wait(Address, Key, Tls, Conn, Had) :-
    get_time(Now),
    with_mutex(dfrl_transport_pool,
               (   take_pooled(Address, Key, Tls, Now, Conn0, Had0)
               ->  Result = taken(Conn0, Had0)
               ;   pinging(Address, _, _, Until), Now < Until
               ->  Result = wait
               ;   Result = none
               )),
    (   Result = taken(Conn, Had)
    ->  true
    ;   Result == wait
    ->  sleep(0.002),
        take_pooled_wait(Address, Key, Tls, Conn, Had)
    ).

%   Prefer a connection with exactly the tokens asked for; a request that
%   needs no tokens takes any; one that needs tokens may upgrade an
%   unauthenticated one. Only a connection of the same TLS identity
%   (or plaintext like the caller) is taken.
take_pooled(Address, Key, Tls, Now, Conn, Had) :-
    sweep_all(Now),
    (   take_entry(Address, Key, Tls, Conn)
    ->  Had = Key
    ;   Key == none
    ->  take_entry(Address, Had, Tls, Conn)
    ;   take_entry(Address, none, Tls, Conn)
    ->  Had = none
    ).

take_entry(Address, Key, Tls, Conn) :-
    pooled(Address, Key, Conn, U, C),
    conn_tls_is(Conn, Tls),
    !,
    retract(pooled(Address, Key, Conn, U, C)).

conn_tls_is(conn(_, Pair, _, _, _), Tls) :-
    (   conn_tls(Pair, T)
    ->  T == Tls
    ;   Tls == none
    ).

usable(Key, Conn, Checked, Now) :-
    healthy(Conn),
    Conn = conn(_, _, _, Info, _),
    server_idle(Key, Info, Idle),
    Now - Checked < Idle * 0.8.

%   How long the server lets this connection be silent (its hello says).
server_idle(none, Info, Idle) :-
    !,
    (   hello_prop(Info, idle(Idle0)) -> Idle = Idle0 ; Idle = 10 ).
server_idle(_, Info, Idle) :-
    (   hello_prop(Info, auth_idle(Idle0)) -> Idle = Idle0 ; Idle = 10 ).

%   An idle pooled connection must have nothing to read: readable means
%   the server closed it (or sent garbage).
healthy(conn(_, Pair, _, _, _)) :-
    stream_pair(Pair, In, _),
    catch(wait_for_input([In], Ready, 0), _, fail),
    Ready == [].

remember_key(conn(_, Pair, _, _, _), Key) :-
    with_mutex(dfrl_transport_pool,
               ( retractall(conn_key(Pair, _)),
                 assertz(conn_key(Pair, Key)) )).

%!  transport_release(+Conn) is det.
%
%   Return Conn to the pool for reuse.

transport_release(Conn) :-
    Conn = conn(_, Pair, _, _, _),
    (   conn_key(Pair, Key)
    ->  release(Conn, Key)
    ;   transport_close(Conn)
    ).

release(Conn, Key) :-
    Conn = conn(Address, Pair, _, _, _),
    get_time(Now),
    with_mutex(dfrl_transport_pool,
               ( retractall(conn_key(Pair, _)),
                 assertz(conn_key(Pair, Key)),
                 assertz(pooled(Address, Key, Conn, Now, Now)),
                 enforce_pool_max,
                 ensure_janitor
               )).

enforce_pool_max :-
    current_prolog_flag(dfrl_pool_max, Max),
    aggregate_all(count, pooled(_, _, _, _, _), N),
    (   N > Max,
        aggregate_all(min(U, C), pooled(_, _, C, U, _), min(_, Oldest))
    ->  retract(pooled(_, _, Oldest, _, _)),
        transport_close(Oldest),
        enforce_pool_max
    ;   true
    ).

%!  transport_discard(+Conn) is det.
%
%   Close Conn instead of returning it to the pool.

transport_discard(Conn) :-
    transport_close(Conn).

%!  transport_drop_pool is det.
%
%   Close every pooled connection and stop the janitor.

transport_drop_pool :-
    with_mutex(dfrl_transport_pool,
               forall(retract(pooled(_, _, C, _, _)), transport_close(C))),
    catch(thread_send_message(dfrl_pool_janitor, stop), _, true).

%!  transport_pool_statistics(-Stats) is det.
%
%   Stats is pool{connections:N, unauthenticated:U, janitor:Bool}.

transport_pool_statistics(pool{connections:N, unauthenticated:U, janitor:J}) :-
    with_mutex(dfrl_transport_pool,
               ( aggregate_all(count, pooled(_, _, _, _, _), N),
                 aggregate_all(count, pooled(_, none, _, _, _), U),
                 ( janitor_running -> J = true ; J = false ) )).

ensure_janitor :-
    (   janitor_running,
        catch(thread_property(dfrl_pool_janitor, status(running)), _, fail)
    ->  true
    ;   catch(thread_create(janitor_loop, _,
                            [alias(dfrl_pool_janitor), detached(true)]),
              _, fail)
    ->  assertz(janitor_running)
    ;   true
    ).

janitor_loop :-
    janitor_period(Period),
    thread_self(Me),
    (   catch(thread_get_message(Me, Msg0, [timeout(Period)]), E, janitor_interrupted(E))
    ->  Msg = Msg0
    ;   Msg = tick
    ),
    (   Msg == stop
    ->  janitor_exit
    ;   catch(janitor_round, E, print_message(warning, E)),
        (   with_mutex(dfrl_transport_pool, janitor_may_exit)
        ->  true
        ;   janitor_loop
        )
    ).

janitor_interrupted('$aborted') :- !, janitor_exit, throw('$aborted').
janitor_interrupted(unwind(A)) :- !, janitor_exit, throw(unwind(A)).
janitor_interrupted(E) :- print_message(warning, E), fail.

janitor_exit :-
    with_mutex(dfrl_transport_pool, retractall(janitor_running)).

janitor_may_exit :-
    \+ pooled(_, _, _, _, _),
    retractall(janitor_running).

janitor_period(Period) :-
    current_prolog_flag(dfrl_keepalive, K),
    with_mutex(dfrl_transport_pool,
               findall(I, ( pooled(_, Key, C, _, _),
                            C = conn(_, _, _, Info, _),
                            server_idle(Key, Info, I) ),
                       Idles)),
    min_list([K|Idles], Min),
    Period is max(0.05, min(1.0, Min / 4)).

%   Close what the peer closed or the server is about to close; ping an
%   authenticated connection silent for the keepalive interval (or half
%   its server's limit, if that is shorter).
janitor_round :-
    get_time(Now),
    Until is Now + 5,
    with_mutex(dfrl_transport_pool,
               ( sweep_all(Now),
                 findall(Entry, due_keepalive(Now, Entry), Due),
                 forall(member(pooled(A, K, C, U, Ch), Due),
                        ( retract(pooled(A, K, C, U, Ch)),
                          assertz(pinging(A, K, C, Until)) )) )),
    forall(member(pooled(A, K, C, U, _), Due),
           (   keepalive_ping(C)
           ->  get_time(Then),
               with_mutex(dfrl_transport_pool,
                          ( retractall(pinging(_, _, C, _)),
                            assertz(pooled(A, K, C, U, Then)) ))
           ;   with_mutex(dfrl_transport_pool, retractall(pinging(_, _, C, _))),
               transport_close(C)
           )).

sweep_all(Now) :-
    forall(( pooled(A, K, C, U, Ch), \+ usable(K, C, Ch, Now) ),
           ( retract(pooled(A, K, C, U, Ch)), transport_close(C) )).

due_keepalive(Now, pooled(A, K, C, U, Ch)) :-
    current_prolog_flag(dfrl_keepalive, Keep),
    pooled(A, K, C, U, Ch),
    K \== none,
    C = conn(_, _, _, Info, _),
    server_idle(K, Info, Idle),
    Now - Ch >= min(Keep, Idle / 2).

keepalive_ping(Conn) :-
    Conn = conn(_, Pair, _, _, RT),
    stream_pair(Pair, In, _),
    Wait is min(RT, 5),
    catch(setup_call_cleanup(
              set_stream(In, timeout(Wait)),
              ( transport_send(Conn, text, ping),
                receive_frame(Conn, keepalive, Reply) ),
              set_stream(In, timeout(RT))),
          _, fail),
    Reply = ok(pong(_)).

%!  transport_close(+Conn) is det.

transport_close(conn(_, Pair, _, _, _)) :-
    retractall(conn_key(Pair, _)),
    retractall(conn_tls(Pair, _)),
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
%   Send Request as a frame and wait for the reply, on a pooled
%   connection to Address if there is a healthy one (given back after an
%   ok reply), else on a new one. If the reply is ok(Result), unify
%   Result; if it is error(error(Formal, _)), throw error(Formal,
%   remote(Address)). Options are those of transport_open/3 plus
%
%     - tokens(+List)   prove these tokens first (privileged requests);
%                       default, for a request that needs them
%                       (node:requires_authentication/1): the current
%                       node's tokens
%     - action(+Action) the permission error's action if they are refused
%     - kind(+Kind)     text (default) or binary
%     - fresh(true)     use a new connection and close it afterwards

transport_request(Address0, Request, Result, Options) :-
    address_normalize(Address0, Address),
    (   option(tokens(Tokens), Options)
    ->  must_be(list, Tokens),
        msort(Tokens, Key)
    ;   catch(node:requires_authentication(Request), _, fail),
        own_tokens(Tokens),
        Tokens \== []
    ->  msort(Tokens, Key)
    ;   Key = none
    ),
    (   option(fresh(true), Options)
    ->  setup_call_cleanup(
            transport_open(Address, Conn, Options),
            ( (   Key == none
              ->  true
              ;   option(action(Action), Options, access),
                  transport_auth(Conn, Key, Action)
              ),
              request_on(Conn, Request, Reply, Options)
            ),
            transport_close(Conn))
    ;   acquire(Address, Key, Conn, Options),
        catch(request_on(Conn, Request, Reply, Options), E,
              ( transport_discard(Conn), throw(E) )),
        (   Reply = ok(_)
        ->  transport_release(Conn)
        ;   transport_discard(Conn)
        )
    ),
    reply_result(Address, Reply, Result).

%   The tokens of the calling thread's node: a node proves its own
%   tokens to its peers for the requests that need a proof.
%   A thread of no node (e.g. a node's settle thread in a process whose
%   nodes are not the default) proves the tokens of all nodes of the
%   process.
own_tokens(Tokens) :-
    catch(node:current_node(Node), _, fail),
    !,
    node:node_property(Node, tokens(Tokens)).
own_tokens(Tokens) :-
    findall(T, ( node:local_node(N),
                 node:node_property(N, tokens(Ts)),
                 member(T, Ts) ), Tokens0),
    sort(Tokens0, Tokens).

request_on(Conn, Request, Reply, Options) :-
    option(kind(Kind), Options, text),
    transport_send(Conn, Kind, Request),
    transport_receive(Conn, Reply, []).

reply_result(_, ok(Result0), Result) :-
    !,
    Result = Result0.
reply_result(Address, error(error(Formal0, _)), _) :-
    !,
    inert_error(error(Formal0, remote(Address)), Error),
    throw(Error).
reply_result(Address, Other, _) :-
    transport_error(Address, protocol(unexpected_reply(Other))).
