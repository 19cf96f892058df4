:- module(transport_pool,
          [ transport_acquire/4,        % +Address, +Tokens, -Conn, +Options
            transport_release/1,        % +Conn
            transport_discard/1,        % +Conn
            transport_drop_pool/0,
            transport_identify/3,       % +Address, -Id, +Options
            transport_pool_statistics/1, % -Stats
            pool_acquire/4              % +Address, +Key, -Conn, +Options
          ]).
:- use_module(transport_conn,
              [ address_normalize/2, transport_open/3, transport_close/1, transport_auth/3,
                transport_send/3, transport_receive/3, transport_peer_id/2, own_tls/2,
                hello_prop/2, conn_key_set/2, conn_key/2, conn_tls/2, peer_seen/3,
                peer_unreachable/2, peer_unreachable_note/2 ]).
:- use_module(platform_errors, [transport_error/2]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(error), [must_be/2]).
:- use_module(library(option), [option/3]).
:- use_module(library(lists), [member/2, min_list/2]).
:- use_module(library(aggregate), [aggregate_all/3]).

/** <module> Pooled connections to platforms, kept alive by a janitor

The connections of transport.pl that are reused: each is pooled under
what was proved on it, found healthy or replaced when taken again, and
kept alive with pings by a janitor thread while the pool is not empty;
and "which node answers at this address?" (transport_identify/3), from a
pooled connection, a hello seen lately or a new connection that is then
pooled.
*/

%!  pool_acquire(+Address, +Key, -Conn, +Options) is det.
%
%   As transport_acquire/4 with Key the sorted tokens, or `none`.

pool_acquire(Address, Key, Conn, Options) :-
    acquire(Address, Key, Conn, Options).

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
    conn_key_set(Pair, Key).

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
               ( conn_key_set(Pair, Key),
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
                transport_receive(Conn, Reply, [phase(keepalive)]) ),
              set_stream(In, timeout(RT))),
          _, fail),
    Reply = ok(pong(_)).
