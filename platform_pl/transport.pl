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
:- use_module(platform_errors, [transport_error/2, inert_error/2]).
:- use_module(transport_conn,
              [ address_normalize/2, address_link/2, transport_open/3, transport_close/1,
                transport_auth/3, transport_send/3, transport_receive/3, transport_peer_id/2,
                token_proof/3, open_key/1 ]).
:- use_module(transport_pool,
              [ transport_acquire/4, transport_release/1, transport_discard/1,
                transport_drop_pool/0, transport_identify/3, transport_pool_statistics/1,
                pool_acquire/4 ]).
%   Eager imports (not autoload/2): see node_connection.pl.
:- use_module(library(error), [must_be/2]).
:- use_module(library(option), [option/2, option/3]).
:- use_module(library(lists), [member/2]).

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

One connection is transport_conn.pl's, the pool, its janitor and
transport_identify/3 are transport_pool.pl's; this module re-exports
them and makes requests.
*/

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
%     - kind(+Kind)     text (default), binary, or auto: binary on a
%                       connection that proves tokens (a node decodes a
%                       binary frame only from an authenticated peer),
%                       else text. A term that carries packed vectors
%                       (float_vectors.pl) costs ~10 bytes a float in
%                       binary, but its text escapes every byte and is
%                       parsed by read_term/3 (1 MB: ~200 ms a side).
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
    option(kind(Kind0), Options, text),
    request_kind(Kind0, Key, Kind),
    ReqOptions = [kind(Kind)|Options],
    (   option(fresh(true), Options)
    ->  setup_call_cleanup(
            transport_open(Address, Conn, Options),
            ( (   Key == none
              ->  true
              ;   option(action(Action), Options, access),
                  transport_auth(Conn, Key, Action)
              ),
              request_on(Conn, Request, Reply, ReqOptions)
            ),
            transport_close(Conn))
    ;   pool_acquire(Address, Key, Conn, Options),
        catch(request_on(Conn, Request, Reply, ReqOptions), E,
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

request_kind(auto, Key, Kind) :-
    !,
    (   ( Key == none ; Key == [] )
    ->  Kind = text
    ;   Kind = binary
    ).
request_kind(Kind, _, Kind).

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
