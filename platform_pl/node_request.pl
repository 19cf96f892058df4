:- module(node_request,
          [ request_handle/4,           % +Request, +Ctx, -Reply, -After
            request_reply/2             % +Out, +Reply
          ]).
:- use_module(wire, [frame_write/3]).
:- use_module(node_ctx, [ctx_node/2, ctx_peer_name/2]).
:- use_module(node_registry, [node_property/2, node_option/3, ctx_authorized/1]).

/** <module> Serving one request on a node's connection

A request is checked against the node's policy first: a request that
needs a proved token (hook node:requires_authentication/1) from a peer
that proved none, or one that sends an agent or code from a TLS peer
outside the node's tls_peers(Names), gets a permission error. Then the
first clause of the multifile hook node:platform_request/4 that
succeeds serves it; a request no clause serves gets a domain error
naming it. Replies are written as text frames; an error's context,
which may hold blobs that cannot be written and read back, is dropped.
*/

%!  request_handle(+Request, +Ctx, -Reply, -After) is det.
%
%   Reply is the answer to Request on the connection Ctx (or `none`: the
%   handler wrote it), After what the connection does next, as
%   node:platform_request/4 says (`true`, `close`, continue(Goal) or a
%   goal to run after the reply, ending the connection). Errors a
%   handler raises are the caller's to turn into error(E) replies.

request_handle(Request, Ctx, Reply, After) :-
    (   \+ callable(Request)
    ->  unknown_request(Request, Reply),
        After = true
    ;   node:requires_authentication(Request),
        \+ ctx_authorized(Ctx)
    ->  refusal(Request, Ctx, 'this request needs a proved token', Reply),
        After = true
    ;   restricted_to_tls_peers(Request),
        \+ tls_peer_allowed(Ctx)
    ->  (   ctx_peer_name(Ctx, Peer) -> true ; Peer = none ),
        refusal(Request, Ctx, not_in_tls_peers(Peer), Reply),
        After = true
    ;   node:platform_request(Request, Ctx, Reply0, After0)
    ->  Reply = Reply0,
        After = After0
    ;   unknown_request(Request, Reply),
        After = true
    ).

refusal(Request, Ctx, Why, error(error(permission_error(request, platform, Here),
                                       context(Name/Arity, Why)))) :-
    ctx_node(Ctx, Node),
    node_property(Node, address(Here)),
    functor(Request, Name, Arity).

%   An unknown request is answered with its name and arity only: the
%   request itself may be large (and echoing it back is the peer's
%   work, not ours).
unknown_request(Request, error(error(domain_error(platform_request, What), _))) :-
    (   callable(Request)
    ->  functor(Request, Name, Arity),
        What = Name/Arity
    ;   What = not_callable
    ).

%   Requests that send an agent or code: with tls_peers(Names), only
%   from a peer whose certificate names one of Names.
restricted_to_tls_peers(transfer(_, _, _, _, _)).
restricted_to_tls_peers(transfer(_, _, _, _, _, _)).
restricted_to_tls_peers(commit(_)).
restricted_to_tls_peers(load_code(_, _)).
restricted_to_tls_peers(execute(_, _)).

tls_peer_allowed(Ctx) :-
    ctx_node(Ctx, Node),
    node_option(Node, tls_peers, Names),
    (   Names == any
    ->  true
    ;   ctx_peer_name(Ctx, Name),
        memberchk(Name, Names)
    ).

%!  request_reply(+Out, +Reply) is det.
%
%   Write Reply as a text frame to Out; of an error(E) reply only the
%   formal of E is sent, as remote_failure(Text) if it holds a stream,
%   clause reference or other blob that cannot be read back.

request_reply(Out, Reply) :-
    sanitize_reply(Reply, Safe),
    frame_write(Out, text, Safe).

sanitize_reply(error(E), error(error(Safe, _))) :-
    !,
    (   E = error(Formal, _)
    ->  true
    ;   Formal = E
    ),
    (   writable_term(Formal)
    ->  Safe = Formal
    ;   format(string(Text), '~p', [Formal]),
        Safe = remote_failure(Text)
    ).
sanitize_reply(Reply, Reply).

%   Linear in the size of T (sub_term/2 is quadratic on deep terms: a
%   reply echoing a 200 KB operator chain took a minute of CPU).
writable_term(T) :-
    (   compound(T)
    ->  compound_name_arity(T, _, A),
        writable_args(1, A, T)
    ;   blob(T, Type)
    ->  memberchk(Type, [text, reserved_symbol])
    ;   true
    ).

writable_args(I, A, _) :-
    I > A,
    !.
writable_args(I, A, T) :-
    arg(I, T, X),
    writable_term(X),
    I1 is I + 1,
    writable_args(I1, A, T).
