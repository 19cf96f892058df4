:- module(transport_conn,
          [ address_normalize/2,        % +Address, -Host:Port
            address_link/2,             % ?Host:Port, ?(Host,Port)
            transport_open/3,           % +Address, -Conn, +Options
            transport_close/1,          % +Conn
            transport_auth/3,           % +Conn, +Tokens, +Action
            transport_send/3,           % +Conn, +Kind, +Term
            transport_receive/3,        % +Conn, -Reply, +Options
            transport_peer_id/2,        % +Conn, -Id
            token_proof/3,              % +Token, +Nonce, -Proof
            open_key/1,                 % -Token
            own_tls/2,                  % +Options, -Dir
            hello_prop/2,               % +Info, ?Prop
            conn_key_set/2,             % +Pair, +Key
            conn_key/2,                 % ?Pair, ?Key
            conn_tls/2,                 % ?Pair, ?Dir
            peer_seen/3,                % ?Address, ?Id, ?Time
            peer_unreachable/2,         % ?Address, ?Time
            peer_unreachable_note/2     % +Address, +Time
          ]).
:- use_module(wire, [frame_write/3, frame_read/3, wire_version/1]).
:- use_module(platform_errors, [transport_error/2, inert_error/2]).
:- use_module(tls, [tls_connect/5]).
:- use_module(timed_connect, [timed_connect/4]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(socket), [tcp_setopt/2]).
:- use_module(library(error), [must_be/2, domain_error/2]).
:- use_module(library(option), [option/3]).
:- use_module(library(sha), [hmac_sha/4]).
:- use_module(library(lists), [member/2]).

/** <module> One connection to a platform: open, prove tokens, send, receive

The connection of transport.pl's client side (its module doc has the
protocol): connect with a timeout (plaintext or TLS), read the hello,
prove tokens with HMACs of its nonce, send frames and read replies with
a reply timeout. A connection is conn(Address, Pair, Nonce, Info,
ReplyTimeout); what was proved on it and whether it is TLS are kept by
its stream pair (conn_key/2, conn_tls/2) for the pool
(transport_pool.pl), and the id each address announced in its hello for
"is this address that node?" (peer_seen/3).
*/

:- predicate_options(transport_open/3, 3,
                     [ connect_timeout(number),
                       reply_timeout(number),
                       tls(any)
                     ]).

:- dynamic
    conn_key/2,                 % Pair, Key: what was proved on it
    conn_tls/2,                 % Pair, Dir: a TLS connection
    peer_seen/3,                % Address, Id, Time: the id in its last hello
    peer_unreachable/2.         % Address, Time: the last failed identify

%!  conn_key_set(+Pair, +Key) is det.
%!  conn_key(?Pair, ?Key) is nondet.
%!  conn_tls(?Pair, ?Dir) is nondet.
%
%   What was proved on the connection of stream Pair (`none`, or the
%   sorted tokens); the certificate folder of a TLS connection.

conn_key_set(Pair, Key) :-
    with_mutex(dfrl_transport_pool,
               ( retractall(conn_key(Pair, _)),
                 assertz(conn_key(Pair, Key)) )).

%!  peer_seen(?Address, ?Id, ?Time) is nondet.
%!  peer_unreachable(?Address, ?Time) is nondet.
%!  peer_unreachable_note(+Address, +Time) is det.
%
%   The id Address announced in its last hello, and when; when a
%   connection to Address last failed (transport_identify/3), noted.

peer_unreachable_note(Address, Now) :-
    with_mutex(dfrl_transport_pool,
               ( retractall(peer_unreachable(Address, _)),
                 assertz(peer_unreachable(Address, Now)) )).

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

%!  own_tls(+Options, -Dir) is det.
%
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

%!  transport_peer_id(+Conn, -Id) is semidet.
%
%   Id is the node id the peer announced in its hello on Conn (an atom
%   of 32 hex digits). Fails for a peer that announced none.

transport_peer_id(conn(_, _, _, Info, _), Id) :-
    hello_prop(Info, id(Id)).

%!  hello_prop(+Info, ?Prop) is semidet.
%
%   Prop is in the hello's Info.

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
